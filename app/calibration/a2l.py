"""Open an A2L (ASAM MCD-2 MC): parse once with pya2ldb, then answer from a cache.

``open_a2l(data, cache_dir=...)`` keys everything by the SHA-256 of the file's bytes:

1. ``<sha256>.json`` in ``cache_dir`` exists → load it (tens of milliseconds even for a
   2 MB A2L; pya2ldb is not imported).
2. Otherwise the bytes are written to a private temporary directory inside ``cache_dir``
   and parsed by pya2ldb in a child process (:mod:`app.calibration.a2l_extract`), which
   writes pya2ldb's ``.a2ldb`` database and the JSON summary. Both are moved into place
   with ``os.replace``, the summary last, so a concurrent opener sees either no entry or a
   complete one; two processes parsing the same new file both publish identical files.

Nothing is ever written next to an input path. A file that is not an A2L (no ``/begin
PROJECT``, no MODULE, a syntax error pya2ldb cannot get past, binary data) raises
``InputError(..., field="a2l")`` and leaves no cache entry. See
``docs/calibration.md#a2l-import``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
from collections import OrderedDict
from collections.abc import Iterable
from pathlib import Path

from app.calibration.model import CHARACTERISTIC_TYPES, AxisPts, Characteristic
from app.calibration.summary import Summary, from_json
from app.io.errors import InputError, too_large

#: Largest A2L accepted; production A2Ls are 1–20 MB.
MAX_A2L_BYTES = 64 * 1024 * 1024
#: A parse that takes longer than this is abandoned (a 2 MB A2L takes ~10 s).
PARSE_TIMEOUT_S = 600.0
#: Parser messages kept as :attr:`A2lFile.warnings`.
MAX_WARNINGS = 50
MAX_PAGE = 1000
#: Opened A2Ls kept in memory (a 2 MB A2L's objects take a few tens of MB).
MEMO_SIZE = 4

_PROJECT = re.compile(rb"/begin\s+PROJECT\b")
_MODULE = re.compile(rb"/begin\s+MODULE\b")
_END_MODULE = re.compile(rb"/end\s+MODULE\b")
_END_PROJECT = re.compile(rb"/end\s+PROJECT\b")
_PARSER_MESSAGE = re.compile(r"\[(?:error|warning)\]\s*(.*)$", re.IGNORECASE)
_UTF8_BOM = b"\xef\xbb\xbf"
_MEMO: OrderedDict[tuple[str, int, int], A2lFile] = OrderedDict()
_MEMO_LOCK = threading.Lock()


class A2lFile:
    """The CHARACTERISTICs (VALUE, CURVE, MAP, VAL_BLK) and AXIS_PTS of one A2L, by name.

    ``characteristics`` are in name order; ``warnings`` are the parser's complaints about
    parts it skipped (the file still opened); ``skipped`` counts characteristics of other
    types (ASCII, CUBOID, …); ``from_cache`` tells whether this open re-used a parse.
    """

    def __init__(self, sha256: str, summary: Summary, *, from_cache: bool) -> None:
        self.sha256 = sha256
        self.module = summary.module
        self.characteristics: tuple[Characteristic, ...] = tuple(
            sorted(summary.characteristics, key=lambda c: (c.name.lower(), c.name))
        )
        self.axis_pts: dict[str, AxisPts] = summary.axis_pts
        self.warnings: tuple[str, ...] = tuple(summary.warnings)
        self.skipped: dict[str, int] = summary.skipped
        self.from_cache = from_cache
        self._by_name = {c.name: c for c in reversed(self.characteristics)}
        self._haystack = [f"{c.name}\n{c.description}".lower() for c in self.characteristics]

    def __len__(self) -> int:
        return len(self.characteristics)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def get(self, name: str) -> Characteristic:
        """The characteristic called ``name`` (exact, case-sensitive as in the A2L)."""
        try:
            return self._by_name[name]
        except KeyError:
            raise InputError(f"no characteristic {name!r} in the A2L", field="map") from None

    def search(
        self, query: str = "", types: Iterable[str] | str = (), limit: int = 100, offset: int = 0
    ) -> tuple[int, list[Characteristic]]:
        """``(total, page)``: characteristics whose name or description contains ``query``
        (case-insensitive; every whitespace-separated word must occur), of the given
        ``types`` (all when empty; a list or ``"MAP,CURVE"``), in name order, ``limit``
        from ``offset``."""
        wanted = _types(types)
        if not 0 <= limit <= MAX_PAGE:
            raise InputError(f"limit must be between 0 and {MAX_PAGE}, got {limit}", field="limit")
        if offset < 0:
            raise InputError(f"offset must be 0 or more, got {offset}", field="offset")
        words = query.lower().split()
        hits = [
            c
            for c, text in zip(self.characteristics, self._haystack, strict=True)
            if (not wanted or c.type in wanted) and all(w in text for w in words)
        ]
        return len(hits), hits[offset : offset + limit]


def open_a2l(data: bytes, *, cache_dir: Path) -> A2lFile:
    """Open the A2L ``data``, parsing it only when ``cache_dir`` has no summary of it."""
    if len(data) > MAX_A2L_BYTES:
        raise too_large(f"A2L is {len(data)} bytes, the limit is {MAX_A2L_BYTES}", field="a2l")
    sha256 = hashlib.sha256(data).hexdigest()
    cached = open_cached(sha256, cache_dir=cache_dir)
    if cached is not None:
        return cached
    _sniff(data)
    Path(cache_dir).mkdir(parents=True, exist_ok=True)
    summary = _parse(data, sha256, Path(cache_dir))
    return A2lFile(sha256, summary, from_cache=False)


def open_cached(sha256: str, *, cache_dir: Path) -> A2lFile | None:
    """The A2L with content hash ``sha256`` from ``cache_dir``, ``None`` when not cached.

    The last :data:`MEMO_SIZE` A2Ls loaded stay in memory while their summary file is
    unchanged (same modification time and size), so a server answers repeated listings
    without reading the summary again."""
    path = cached_paths(sha256, cache_dir=cache_dir)[0]
    try:
        stat = path.stat()
    except OSError:
        return None
    key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    with _MEMO_LOCK:
        a2l = _MEMO.get(key)
        if a2l is not None:
            _MEMO.move_to_end(key)
            return a2l
    summary = _load(path)
    if summary is None:
        return None
    a2l = A2lFile(sha256, summary, from_cache=True)
    with _MEMO_LOCK:
        _MEMO[key] = a2l
        while len(_MEMO) > MEMO_SIZE:
            _MEMO.popitem(last=False)
    return a2l


def cached_paths(sha256: str, *, cache_dir: Path) -> tuple[Path, Path]:
    """``(summary.json, pya2ldb .a2ldb)`` of a cached A2L (they exist after an open)."""
    return Path(cache_dir) / f"{sha256}.json", Path(cache_dir) / f"{sha256}.a2ldb"


def _types(types: Iterable[str] | str) -> frozenset[str]:
    if isinstance(types, str):
        types = types.split(",")
    wanted = frozenset(t.strip().upper() for t in types if t.strip())
    unknown = sorted(wanted - set(CHARACTERISTIC_TYPES))
    if unknown:
        known = ", ".join(CHARACTERISTIC_TYPES)
        raise InputError(
            f"unknown characteristic type {', '.join(unknown)}; use {known}", field="type"
        )
    return wanted


def _load(path: Path) -> Summary | None:
    """The cached summary, or ``None`` when absent or unreadable (then it is re-parsed)."""
    try:
        return from_json(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _sniff(data: bytes) -> None:
    """Refuse what cannot be an A2L before starting a parser (pya2ldb accepts anything)."""
    head = data[:65536]
    if not data.strip():
        raise InputError("the A2L file is empty", field="a2l")
    if b"\x00" in head:
        raise InputError("not an A2L file: it is binary (A2L is ASAM MCD-2 MC text)", field="a2l")
    if not _PROJECT.search(data):
        raise InputError("not an A2L file: no '/begin PROJECT' block (ASAM MCD-2 MC)", field="a2l")
    if not _MODULE.search(data):
        raise InputError("not an A2L file: no '/begin MODULE' block in the PROJECT", field="a2l")
    # pya2ldb reads a file cut between two blocks as a smaller whole one: a truncated upload
    # would become an ECU missing its later characteristics, without a word.
    for end, block in ((_END_MODULE, "MODULE"), (_END_PROJECT, "PROJECT")):
        if not end.search(data):
            raise InputError(
                f"the A2L file ends before '/end {block}': it is truncated", field="a2l"
            )


def _parse(data: bytes, sha256: str, cache_dir: Path) -> Summary:
    """Parse in a child process inside a private directory, then publish atomically."""
    work = Path(tempfile.mkdtemp(prefix=".a2l-", dir=cache_dir))
    try:
        text, encoding = _text(data)
        source = work / "input.a2l"
        source.write_bytes(text)
        log = work / "parser.log"
        with log.open("wb") as out:
            try:
                subprocess.run(
                    [
                        sys.executable,
                        "-m",
                        "app.calibration.a2l_extract",
                        str(source),
                        str(work),
                        encoding,
                    ],
                    cwd=work,
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    timeout=PARSE_TIMEOUT_S,
                    check=False,
                    env={**os.environ, "PYTHONIOENCODING": "utf-8", "COLUMNS": "200"},
                )
            except subprocess.TimeoutExpired:
                raise InputError(
                    f"the A2L took longer than {PARSE_TIMEOUT_S:.0f} s to parse", field="a2l"
                ) from None
        summary_path = work / "summary.json"
        if not summary_path.exists():
            raise InputError(_failure(work, log), field="a2l")
        doc = json.loads(summary_path.read_text(encoding="utf-8"))
        doc["warnings"] = _warnings(log)
        summary_path.write_text(json.dumps(doc), encoding="utf-8")
        json_path, db_path = cached_paths(sha256, cache_dir=cache_dir)
        database = work / "input.a2ldb"
        if database.exists():
            os.replace(database, db_path)
        os.replace(summary_path, json_path)
        return from_json(doc)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _text(data: bytes) -> tuple[bytes, str]:
    """The bytes pya2ldb reads and their encoding: UTF-8 (BOM dropped) when they decode
    as such, else Latin-1 (the A2L default)."""
    if data.startswith(_UTF8_BOM):
        data = data[len(_UTF8_BOM) :]
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return data, "latin-1"
    return data, "utf-8"


def _failure(work: Path, log: Path) -> str:
    error = work / "error.json"
    if error.exists():
        message = json.loads(error.read_text(encoding="utf-8"))["message"]
    else:
        message = "the A2L parser stopped without a result"
    first = _warnings(log)[:1]
    return f"{message} ({first[0]})" if first and first[0] not in message else message


def _warnings(log: Path) -> list[str]:
    """The parser's ``[error]``/``[warning]`` lines (``Invalid param: … [line:col]``)."""
    messages: list[str] = []
    with log.open("r", encoding="utf-8", errors="replace") as lines:
        for line in lines:
            match = _PARSER_MESSAGE.search(line.rstrip())
            if match and match.group(1):
                messages.append(match.group(1).strip())
                if len(messages) >= MAX_WARNINGS:
                    break
    return messages
