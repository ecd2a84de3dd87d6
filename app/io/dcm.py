"""Maps as DAMOS DCM 2.0 text (``KONSERVIERUNG_FORMAT 2.0``), the exchange format that
calibration tools (INCA, CANape, …) import and export.

A 1-D map is a ``KENNLINIE name n`` block, a 2-D map a ``KENNFELD name nx ny`` block::

    KENNFELD nox_map 4 3
       LANGNAME "NOx raw emission"
       EINHEIT_X "rpm"
       EINHEIT_Y "mg/stroke"
       EINHEIT_W "ppm"
    *SSTX	speed
    *SSTY	fuel
       ST/X   500.0   1500.0   2500.0   3500.0
       ST/Y   0.0
       WERT   1.0   2.0   3.5   3.0
       ST/Y   20.0
       WERT   …
    END

X is the table's first axis and Y its second: the ``WERT`` line after ``ST/Y y_j`` holds
``values[:, j]``. Axis names travel in ``*SSTX`` / ``*SSTY`` lines (the axis-reference
comments INCA writes in group maps; other tools read them as comments). At most six
numbers per line; numbers are written with ``repr`` so an export parses back bit-exactly.
The parser also reads ``GRUPPEN…``/``FEST…`` variants of both blocks and skips every other
block (``FESTWERT``, ``FUNKTIONEN``, …). :func:`blocks_to_dcm` writes calibration values
keyed by their A2L names, whose axes need not increase
(``docs/calibration.md#values``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from app.io.errors import InputError
from estimation.errors import ShapeError
from estimation.table import Axis, Table

PER_LINE = 6
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\[\]]*$")
_WORD = re.compile(r'"([^"]*)"|(\S+)')
_CURVES = {"KENNLINIE", "GRUPPENKENNLINIE", "FESTKENNLINIE"}
_MAPS = {"KENNFELD", "GRUPPENKENNFELD", "FESTKENNFELD"}
_OTHER_BLOCKS = {
    "FESTWERT",
    "FESTWERTEBLOCK",
    "STUETZSTELLENVERTEILUNG",
    "TEXTSTRING",
    "FUNKTIONEN",
    "VARIANTENKODIERUNG",
    "MODULKOPF",
}


def map_to_dcm(table: Table, *, name: str, unit: str = "", description: str = "") -> str:
    """One map as a complete DCM 2.0 file."""
    return maps_to_dcm([(name, table, unit)], descriptions={name: description})


def maps_to_dcm(
    blocks: Sequence[tuple[str, Table, str]], *, descriptions: dict[str, str] | None = None
) -> str:
    """Several ``(name, table, value unit)`` maps in one DCM 2.0 file."""
    lines = ["* DCM export by mapwise", "KONSERVIERUNG_FORMAT 2.0", ""]
    for name, table, unit in blocks:
        lines += _block(table, name, unit, (descriptions or {}).get(name, ""))
        lines.append("")
    return "\n".join(lines)


def _block(table: Table, name: str, unit: str, description: str) -> list[str]:
    axes = [(a.name, a.unit, a.breakpoints) for a in table.axes]
    return _block_lines(name, axes, table.values, unit, description)


class DcmBlock(NamedTuple):
    """One curve or map for :func:`blocks_to_dcm`: ``axes`` are ``(name, unit, points)``
    in axis order; ``prefix`` is ``""``, ``"GRUPPEN"`` (shared axes) or ``"FEST"`` (fixed
    axes), giving ``KENNLINIE``/``GRUPPENKENNLINIE``/``FESTKENNLINIE`` and likewise
    ``…KENNFELD``."""

    name: str
    axes: Sequence[tuple[str, str, Sequence[float]]]
    values: np.ndarray
    unit: str = ""
    description: str = ""
    prefix: str = ""


def blocks_to_dcm(blocks: Sequence[DcmBlock]) -> str:
    """Several curves/maps in one DCM 2.0 file. Unlike :func:`maps_to_dcm` the axis points
    need not increase (ECU axes as stored, e.g. point indices)."""
    lines = ["* DCM export by mapwise", "KONSERVIERUNG_FORMAT 2.0", ""]
    for block in blocks:
        lines += _block_lines(
            block.name,
            block.axes,
            np.asarray(block.values),
            block.unit,
            block.description,
            prefix=block.prefix,
        )
        lines.append("")
    return "\n".join(lines)


def _block_lines(
    name: str,
    axes: Sequence[tuple[str, str, Sequence[float]]],
    values: np.ndarray,
    unit: str,
    description: str,
    *,
    prefix: str = "",
) -> list[str]:
    if prefix not in ("", "GRUPPEN", "FEST"):
        raise ValueError(f"DCM block prefix must be '', 'GRUPPEN' or 'FEST', got {prefix!r}")
    if not _NAME.match(name):
        raise InputError(
            f"DCM name {name!r} must start with a letter or '_' and hold only letters, "
            "digits, '_', '.', '[', ']'",
            field="name",
        )
    if len(axes) not in (1, 2):
        raise InputError(
            f"DCM holds 1-D (KENNLINIE) and 2-D (KENNFELD) maps; this one has {len(axes)} axes",
            field="table",
        )
    x_name, x_unit, x_points = axes[0]
    head = (
        f"{prefix}KENNLINIE {name} {len(x_points)}"
        if len(axes) == 1
        else f"{prefix}KENNFELD {name} {len(x_points)} {len(axes[1][2])}"
    )
    lines = [head]
    if description:
        lines.append(f'   LANGNAME "{_text(description)}"')
    lines.append(f'   EINHEIT_X "{_text(x_unit)}"')
    if len(axes) == 2:
        lines.append(f'   EINHEIT_Y "{_text(axes[1][1])}"')
    lines.append(f'   EINHEIT_W "{_text(unit)}"')
    lines.append(f"*SSTX\t{_text(x_name)}")
    if len(axes) == 2:
        lines.append(f"*SSTY\t{_text(axes[1][0])}")
    lines += _numbers("ST/X", x_points)
    if len(axes) == 1:
        lines += _numbers("WERT", values)
    else:
        for j, y in enumerate(axes[1][2]):
            lines += _numbers("ST/Y", [y])
            lines += _numbers("WERT", values[:, j])
    lines.append("END")
    return lines


def _text(value: str) -> str:
    """A one-line string safe inside DCM double quotes."""
    return " ".join(str(value).replace('"', "'").split())


def _numbers(keyword: str, values: Sequence[float] | np.ndarray) -> list[str]:
    values = [repr(float(v)) for v in values]
    return [
        f"   {keyword:<6}" + "   ".join(values[i : i + PER_LINE])
        for i in range(0, len(values), PER_LINE)
    ]


@dataclass
class _Block:
    kind: str
    name: str
    line: int
    sizes: list[int]
    description: str = ""
    units: dict[str, str] = field(default_factory=dict)
    axis_names: dict[str, str] = field(default_factory=dict)
    x: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    rows: list[list[float]] = field(default_factory=list)


def parse_dcm(text: str) -> list[_Block]:
    """Every KENNLINIE/KENNFELD block of a DCM file (other blocks skipped)."""
    blocks: list[_Block] = []
    current: _Block | None = None
    skipping: tuple[str, int] | None = None
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("*"):
            if current is not None and line[:5] in ("*SSTX", "*SSTY"):
                current.axis_names[line[4]] = line[5:].strip()
            continue
        if skipping is not None:
            if line == "END":
                skipping = None
            continue
        words = _split(line, number)
        keyword = words[0]
        if current is None:
            if keyword in _CURVES | _MAPS:
                current = _start(words, number)
            elif keyword in _OTHER_BLOCKS:
                skipping = (keyword, number)
            elif keyword == "KONSERVIERUNG_FORMAT":
                if words[1:] and words[1] not in ("2.0", "1.0"):
                    raise InputError(
                        f"line {number}: KONSERVIERUNG_FORMAT {words[1]} is not supported (2.0)",
                        field=f"line {number}",
                        line=number,
                    )
            else:
                raise InputError(
                    f"line {number}: unexpected {keyword!r} outside a block",
                    field=f"line {number}",
                    line=number,
                )
            continue
        if keyword == "END":
            blocks.append(_finish(current, number))
            current = None
        else:
            _add(current, words, number)
    if current is not None:
        raise InputError(
            f"line {current.line}: {current.kind} {current.name} has no END",
            field=f"line {current.line}",
            line=current.line,
        )
    if skipping is not None:
        raise InputError(
            f"line {skipping[1]}: {skipping[0]} block has no END",
            field=f"line {skipping[1]}",
            line=skipping[1],
        )
    return blocks


def _split(line: str, number: int) -> list[str]:
    """Words of a line; a double-quoted string is one word (without its quotes)."""
    if line.count('"') % 2:
        raise InputError(
            f"line {number}: unterminated string (odd number of '\"')",
            field=f"line {number}",
            line=number,
        )
    return [m[1] if m[1] is not None else m[2] for m in _WORD.finditer(line)]


def _start(words: list[str], number: int) -> _Block:
    kind = words[0]
    want = 1 if kind in _CURVES else 2
    if len(words) != 2 + want:
        raise InputError(
            f"line {number}: expected '{kind} name {'n' if want == 1 else 'nx ny'}'",
            field=f"line {number}",
            line=number,
        )
    try:
        sizes = [int(w) for w in words[2:]]
    except ValueError:
        raise InputError(
            f"line {number}: {kind} {words[1]}: sizes must be integers, got {words[2:]}",
            field=f"line {number}",
            line=number,
        ) from None
    if any(s < 2 for s in sizes):
        raise InputError(
            f"line {number}: {kind} {words[1]}: needs at least 2 points per axis, got {sizes}",
            field=f"line {number}",
            line=number,
        )
    return _Block(kind, words[1], number, sizes)


def _add(block: _Block, words: list[str], number: int) -> None:
    keyword = words[0]
    where = f"line {number} ({block.kind} {block.name})"
    if keyword in ("EINHEIT_X", "EINHEIT_Y", "EINHEIT_W"):
        block.units[keyword[-1]] = words[1] if len(words) > 1 else ""
    elif keyword == "LANGNAME":
        block.description = words[1] if len(words) > 1 else ""
    elif keyword in ("ST/X", "ST/Y", "WERT"):
        values = _floats(words[1:], where, number)
        if keyword == "ST/X":
            block.x += values
        elif keyword == "ST/Y":
            block.y += values
            block.rows.append([])
        elif block.kind in _MAPS:
            if not block.rows:
                raise InputError(
                    f"{where}: WERT before the first ST/Y", field=f"line {number}", line=number
                )
            block.rows[-1] += values
        else:
            block.rows = [block.rows[0] + values] if block.rows else [values]
    elif keyword in ("ST_TX/X", "ST_TX/Y", "TEXT"):
        raise InputError(
            f"{where}: text values ({keyword}) are not supported; export numeric values",
            field=f"line {number}",
            line=number,
        )
    # FUNKTION, DISPLAYNAME, VAR and unknown keywords carry nothing we need.


def _floats(words: list[str], where: str, number: int) -> list[float]:
    out = []
    for word in words:
        try:
            value = float(word)
        except ValueError:
            raise InputError(
                f"{where}: non-numeric value {word!r}", field=f"line {number}", line=number
            ) from None
        if not np.isfinite(value):
            raise InputError(
                f"{where}: {word} is not allowed (values must be finite)",
                field=f"line {number}",
                line=number,
            )
        out.append(value)
    return out


def _finish(block: _Block, end_line: int) -> _Block:
    where = f"line {block.line} ({block.kind} {block.name})"
    nx = block.sizes[0]

    def fail(message: str) -> InputError:
        return InputError(f"{where}: {message}", field=f"line {block.line}", line=block.line)

    if len(block.x) != nx:
        raise fail(f"{len(block.x)} ST/X values, the header says {nx}")
    if block.kind in _MAPS:
        ny = block.sizes[1]
        if len(block.y) != ny:
            raise fail(f"{len(block.y)} ST/Y values, the header says {ny}")
        for j, row in enumerate(block.rows):
            if len(row) != nx:
                raise fail(f"{len(row)} WERT values after ST/Y {block.y[j]!r}, expected {nx}")
    elif len(block.rows) != 1 or len(block.rows[0]) != nx:
        got = len(block.rows[0]) if block.rows else 0
        raise fail(f"{got} WERT values, expected {nx}")
    return block


def decode_text(data: bytes | str) -> str:
    """The text of a DCM file: UTF-8 (with or without BOM), else Latin-1."""
    if isinstance(data, str):
        return data
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")  # DCM files from older tools are Latin-1


def map_from_dcm(data: bytes | str, *, name: str | None = None) -> tuple[str, str, Table]:
    """``(block name, value unit, table)`` of the KENNLINIE/KENNFELD called ``name``
    (or of the only one in the file)."""
    blocks = parse_dcm(decode_text(data))
    if not blocks:
        raise InputError("the DCM file holds no KENNLINIE or KENNFELD", field="file")
    if name is None:
        if len(blocks) > 1:
            raise InputError(
                f"the DCM file holds {len(blocks)} maps {[b.name for b in blocks]}; choose one",
                field="name",
            )
        block = blocks[0]
    else:
        block = next((b for b in blocks if b.name == name), None)
        if block is None:
            raise InputError(
                f"no map {name!r} in the DCM file; it holds {[b.name for b in blocks]}",
                field="name",
            )
    return block.name, block.units.get("W", ""), _table(block)


def _table(block: _Block) -> Table:
    try:
        x = Axis(block.axis_names.get("X") or "x", block.units.get("X", ""), block.x)
        if block.kind in _CURVES:
            return Table([x], block.rows[0])
        y = Axis(block.axis_names.get("Y") or "y", block.units.get("Y", ""), block.y)
        return Table([x, y], np.array(block.rows).T)
    except ShapeError as exc:
        raise InputError(
            f"line {block.line} ({block.kind} {block.name}): {exc}",
            field=f"line {block.line}",
            line=block.line,
        ) from None
