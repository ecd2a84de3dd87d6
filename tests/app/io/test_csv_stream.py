"""A dense CSV upload streamed into the store equals the same file read whole.

Every file is uploaded twice through :class:`DatasetService`: once streamed (no size floor)
and once read whole (a floor above its size). The two datasets must agree in every field,
and their stored files in rows, row groups and every value bit for bit (the streamed file
has its row count only in the file's metadata, so the bytes differ there); a file the
stream does not take must come out of both uploads the same, stored or refused with the
same message. Blocks are made small so that every file crosses several block boundaries.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from app.db.engine import Database
from app.db.migrate import upgrade
from app.db.repositories import DatasetRepo
from app.domain import Dataset
from app.io.csv_stream import NotDense, StreamedCsv, _Steps, stream_csv
from app.io.errors import InputError
from app.io.ingest import BINARY_BYTES
from app.services.datasets import DatasetService
from app.store import open_store, open_verified
from app.store.parquet_signals import SignalsFile, SignalsWriter

ROOT = Path(__file__).resolve().parents[3]
ROWS = 3000


@pytest.fixture
def service(tmp_path: Path) -> DatasetService:
    url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    store_url = (tmp_path / "store").as_uri()
    upgrade(url, store_url=store_url)
    return DatasetService(Database(url), open_store(store_url))


def _rows(n: int = ROWS, *, rate: float = 100.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    time = np.arange(n) / rate
    return np.column_stack([time, rng.normal(1000, 300, n), rng.uniform(0, 60, n), -0.0 * time])


def _text(
    rows: np.ndarray,
    header: str = "time [s],n [rpm],q [mg],z",
    *,
    sep: str = ",",
    decimal: str = ".",
    end: str = "\n",
    units_row: str | None = None,
    comment_every: int = 0,
) -> str:
    lines = [header]
    if units_row is not None:
        lines.append(units_row)
    for k, row in enumerate(rows):
        if comment_every and k % comment_every == 0:
            lines.append(f"# marker {k}")
        lines.append(sep.join(repr(float(v)).replace(".", decimal) for v in row))
    return end.join(lines) + end


def _upload(service: DatasetService, data: bytes, *, streamed: bool, **kw: object) -> Dataset:
    floor = 0 if streamed else len(data) + 1
    return service.upload(
        io.BytesIO(data),
        filename="log.csv",
        name=None,
        units=kw.pop("units", None),  # type: ignore[arg-type]
        max_bytes=1 << 30,
        stream_min_bytes=floor,
        **kw,  # type: ignore[arg-type]
    )


def _stored(service: DatasetService, dataset: Dataset) -> tuple:
    """The stored object, decoded (checked against the row's hash): rows, row groups, time
    and every channel's name, unit and values as bytes (bit for bit)."""
    with service.db.read() as s:
        stored = DatasetRepo(s).samples(dataset.id)
    with open_verified(service.store, dataset.id, stored.key, stored.sha256) as f:
        file = SignalsFile.open(f)
        meta = file.reader.metadata
        groups = [meta.row_group(g).num_rows for g in range(meta.num_row_groups)]
        time, columns = file.read()
    return (
        file.rows,
        groups,
        time.tobytes(),
        [(c.name, c.unit, c.values.tobytes()) for c in columns],
    )


def _same(service: DatasetService, data: bytes, **kw: object) -> Dataset:
    """Upload ``data`` streamed and whole; assert they agree; the streamed dataset."""
    _stream(data, **kw)  # it does stream (else both uploads would read it whole)
    whole = _upload(service, data, streamed=False, **dict(kw))
    fast = _upload(service, data, streamed=True, **dict(kw))
    for field in ("rows", "rate_hz", "duration_s", "time_column", "channels", "notes", "source"):
        assert getattr(fast, field) == getattr(whole, field), field
    assert _stored(service, fast) == _stored(service, whole)
    return fast


def _stream(data: bytes, **kw: object) -> StreamedCsv:
    return stream_csv(
        io.BytesIO(data),
        lambda channels: SignalsWriter(os.devnull, channels),
        units=kw.get("units"),  # type: ignore[arg-type]
        time_column=None,
        channels=kw.get("channels"),  # type: ignore[arg-type]
        rate_hz=kw.get("rate_hz"),  # type: ignore[arg-type]
        max_header_bytes=65536,
        max_channels=100,
        min_samples=2,
    )


CASES: dict[str, Callable[[], bytes]] = {
    "comma": lambda: _text(_rows()).encode(),
    "crlf and comments": lambda: _text(_rows(), end="\r\n", comment_every=97).encode(),
    "semicolon, decimal comma, units row": lambda: _text(
        _rows(), "time;n;q;z", sep=";", decimal=",", units_row="s;rpm;mg;-"
    ).encode(),
    "tab": lambda: _text(_rows(), "time\tn [rpm]\tq [mg]\tz", sep="\t").encode(),
    "time in ms": lambda: _text(_rows() * [1e3, 1, 1, 1], "time [ms],n,q,z").encode(),
    "a second time-like column": lambda: _text(_rows(), "time,n,t,z").encode(),  # notes agree
    "utf-8 header with a BOM": lambda: (
        b"\xef\xbb\xbf" + _text(_rows(), "time [s],T [°C],q [mg],z").encode()
    ),
    "no final line end": lambda: _text(_rows()).rstrip("\n").encode(),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_dense_csv_streams_to_the_file_a_whole_read_stores(
    service: DatasetService, case: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("app.io.csv_stream.BLOCK_BYTES", 4096)  # many blocks, odd cuts
    dataset = _same(service, CASES[case]())
    assert dataset.rows == ROWS


def test_channels_units_and_a_row_rate_stream_as_they_read_whole(
    service: DatasetService, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("app.io.csv_stream.BLOCK_BYTES", 4096)
    data = _text(_rows()).encode()
    picked = _same(service, data, channels=["q", "n"], units={"z": "bar"})
    assert [c.name for c in picked.channels] == ["q", "n"]
    no_time = _text(_rows()[:, 1:], "n [rpm],q [mg],z").encode()
    rated = _same(service, no_time, rate_hz=50.0)
    assert rated.rate_hz == pytest.approx(50.0)
    assert rated.time_column == ""
    assert any("50 Hz" in note for note in rated.notes)


def _sparse() -> bytes:
    text = _text(_rows())
    lines = text.splitlines()
    lines[2000] = lines[2000].rsplit(",", 1)[0] + ","  # an empty cell: a sparse export
    return ("\n".join(lines) + "\n").encode()


def _nan() -> bytes:
    return _text(_rows()).replace("\n1", "\nnan", 1).encode()


FALLBACKS: dict[str, Callable[[], bytes]] = {
    "an empty cell": _sparse,
    "a written nan in a channel": lambda: _text(_rows()).encode().replace(b",-0.0\n", b",nan\n", 1),
    "a text cell": lambda: _text(_rows()).encode().replace(b",-0.0\n", b",off\n", 1),
    "time going back": lambda: _text(np.vstack([_rows()[:10], _rows()[5:]])).encode(),
    "a nan time": _nan,
    "Latin-1": lambda: _text(_rows(), "time [s],T [°C],q,z").encode("latin-1"),
    "a control character in a late comment": lambda: (
        _text(_rows(), comment_every=1000).encode().replace(b"# marker 2000", b"# marker\x01 2000")
    ),
}


@pytest.mark.parametrize("case", list(FALLBACKS))
def test_a_file_that_cannot_stream_is_read_whole_with_the_same_outcome(
    service: DatasetService, case: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("app.io.csv_stream.BLOCK_BYTES", 4096)
    monkeypatch.setattr("app.io.csv_stream.HEAD_BYTES", 8192)  # the cases lie past the head
    data = FALLBACKS[case]()
    with pytest.raises(NotDense):
        _stream(data)
    outcomes = []
    for streamed in (False, True):
        try:
            dataset = _upload(service, data, streamed=streamed)
            outcomes.append(({k: getattr(dataset, k) for k in ("rows", "channels", "notes")}, None))
        except InputError as exc:
            outcomes.append((None, (exc.field, str(exc))))
    assert outcomes[0] == outcomes[1]


CONTROL = [b for b in range(128) if BINARY_BYTES.search(bytes([b]))]


@pytest.mark.parametrize("byte", CONTROL)
def test_every_control_character_the_whole_read_refuses_stops_the_stream(
    byte: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("app.io.csv_stream.BLOCK_BYTES", 4096)
    monkeypatch.setattr("app.io.csv_stream.HEAD_BYTES", 8192)
    text = _text(_rows(), comment_every=1000).encode()
    with pytest.raises(NotDense, match="control character"):
        _stream(text.replace(b"# marker 2000", b"# marker" + bytes([byte]) + b" 2000"))


def test_tabs_and_form_feeds_in_a_comment_still_stream(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("app.io.csv_stream.BLOCK_BYTES", 4096)
    monkeypatch.setattr("app.io.csv_stream.HEAD_BYTES", 8192)
    text = _text(_rows(), comment_every=1000).encode()
    assert _stream(text.replace(b"# marker 2000", b"# marker\t\x0c 2000")).rows == ROWS


class _RecordingSink:
    """A sink that records its calls, in order, and fails its ``fail_at``-th write."""

    def __init__(self, fail_at: int | None = None) -> None:
        self.calls: list[tuple[str, float]] = []
        self.fail_at = fail_at

    def write(self, time: np.ndarray, values: object) -> None:
        self.calls.append(("write", float(time[0])))
        if sum(c[0] == "write" for c in self.calls) == self.fail_at:
            raise OSError("no space left on device")

    def close(self) -> str:
        self.calls.append(("close", 0.0))
        return "0" * 64

    def abort(self) -> None:
        self.calls.append(("abort", 0.0))


def _stream_into(sink: _RecordingSink, data: bytes) -> StreamedCsv:
    return stream_csv(
        io.BytesIO(data),
        lambda channels: sink,
        units=None,
        time_column=None,
        channels=None,
        rate_hz=None,
        max_header_bytes=65536,
        max_channels=100,
        min_samples=2,
    )


def test_blocks_are_written_in_order_one_behind_the_parse(monkeypatch: pytest.MonkeyPatch) -> None:
    """The writes run on their own thread (parse and write overlap), yet the sink sees every
    block in order and the close after the last; a failed write stops the stream with its
    error at the next block, the blocks after it never written, and the sink aborted; a
    file found not dense late aborts the sink after its pending write."""
    monkeypatch.setattr("app.io.csv_stream.BLOCK_BYTES", 4096)
    data = _text(_rows()).encode()
    sink = _RecordingSink()
    assert _stream_into(sink, data).rows == ROWS
    writes = [t for name, t in sink.calls if name == "write"]
    assert len(writes) > 20
    assert writes == sorted(writes)
    assert sink.calls[-1][0] == "close"
    assert [name for name, _ in sink.calls].count("close") == 1

    failing = _RecordingSink(fail_at=3)
    with pytest.raises(OSError, match="no space left"):
        _stream_into(failing, data)
    assert [name for name, _ in failing.calls] == ["write"] * 3 + ["abort"]

    lines = _text(_rows(40_000)).encode().split(b"\n")  # past the first MiB read as a head
    lines[-100] += b"\x07"  # a control character near the end
    late = _RecordingSink()
    with pytest.raises(NotDense, match="control character"):
        _stream_into(late, b"\n".join(lines))
    names = [name for name, _ in late.calls]
    assert names[-1] == "abort"
    assert "close" not in names
    assert names.count("write") > 5


def test_more_channels_than_the_limit_do_not_stream() -> None:
    """Without a time column every column is a channel: the limit counts them all."""
    header = ",".join(f"c{j}" for j in range(101))
    data = (header + "\n" + "".join(",".join(["1"] * 101) + "\n" for _ in range(30))).encode()
    with pytest.raises(NotDense, match="channels"):
        _stream(data, rate_hz=10.0)


def test_a_file_over_the_whole_read_limit_streams_or_is_refused_saying_why(
    service: DatasetService,
) -> None:
    def upload(data: bytes) -> Dataset:
        return service.upload(
            io.BytesIO(data),
            filename="a.csv",
            name=None,
            units=None,
            max_bytes=1 << 30,
            max_whole_bytes=1000,
            stream_min_bytes=0,
        )

    assert upload(_text(_rows()).encode()).rows == ROWS
    with pytest.raises(InputError) as refused:
        upload(_sparse())
    assert refused.value.code == "payload_too_large"
    assert "cannot stream" in str(refused.value)
    assert "MAPWISE_MAX_WHOLE_MB" in str(refused.value)
    assert len(service.list(limit=50, offset=0).items) == 1  # nothing stored for the refusal


_MEMORY = """
import io, os, sys
from pathlib import Path
def hwm():
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) // 1024
from app.io.csv_stream import stream_csv
from app.io.ingest import ingest
from app.store.parquet_signals import SignalsFile, SignalsWriter
path, mode = sys.argv[1], sys.argv[2]
ingest(b"time,a\\n0,1\\n1,2\\n")  # imports and pyarrow's pools before the baseline
Path("/proc/self/clear_refs").write_text("5")
before = hwm()
if mode == "stream":
    with open(path, "rb") as f:
        stream_csv(f, lambda c: SignalsWriter(os.devnull, c), units=None, time_column=None,
                   channels=None, rate_hz=None, max_header_bytes=65536, max_channels=100,
                   min_samples=2)
else:
    ingest(Path(path))
print(hwm() - before)
"""


def _growth(path: Path, mode: str) -> int:
    """MiB the process grew by while reading ``path`` (``stream`` or ``whole``)."""
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(_MEMORY), str(path), mode],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
        timeout=300,
    )
    return int(out.stdout.split()[-1])


@pytest.mark.slow
def test_streaming_holds_a_block_not_the_file(tmp_path: Path) -> None:
    """A 12-channel log of about 100 MB (25 blocks) and its first half: streaming grows the
    process by the same amount for both (pyarrow's threads, a few blocks and their columns;
    the time column, 8 bytes a row, is the only part that grows with the file), a whole
    read by more than the file."""
    n, rng = 800_000, np.random.default_rng(1)
    path, half = tmp_path / "big.csv", tmp_path / "half.csv"
    with path.open("w") as f, half.open("w") as h:
        f.write("time," + ",".join(f"c{j}" for j in range(12)) + "\n")
        h.write("time," + ",".join(f"c{j}" for j in range(12)) + "\n")
        for a in range(0, n, 100_000):
            times = np.arange(a, a + 100_000) / 1000.0
            block = np.column_stack([times, rng.normal(size=(100_000, 12))])
            np.savetxt(f, block, delimiter=",", fmt="%.10g")
            if a < n // 2:
                np.savetxt(h, block, delimiter=",", fmt="%.10g")
    size_mb = path.stat().st_size / 2**20
    assert size_mb > 90
    whole, full, part = _growth(path, "whole"), _growth(path, "stream"), _growth(half, "stream")
    assert whole > size_mb  # the test can fail: a whole read holds the file and its columns
    assert full < 0.5 * whole, (full, whole)
    assert abs(full - part) < 30, (full, part)  # half the file, the same memory


@pytest.mark.parametrize("rows", [2, 3, 1000, 1001, 200_001])
@pytest.mark.parametrize("kind", ["logger", "jittered"])
def test_the_streamed_median_step_is_numpys_bit_for_bit(rows: int, kind: str) -> None:
    """The steps are counted by value block by block (few distinct values for a logger, one
    per row when jittered, with merges in between); the median is np.median's."""
    rng = np.random.default_rng(rows)
    if kind == "logger":  # %.6f of k / 100 Hz, as a logger writes it
        time = np.array([float(f"{k / 100:.6f}") for k in range(rows)])
    else:
        time = np.cumsum(rng.uniform(0.005, 0.015, rows))
    steps = _Steps()
    for block in np.array_split(time, max(1, rows // 7000)):
        steps.add(block)
    assert steps.rows == rows
    assert steps.median() == float(np.median(np.diff(time)))
    if kind == "logger":
        assert steps.values.size < 1000  # what it holds does not grow with the rows
