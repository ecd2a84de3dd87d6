"""``mapwise a2l list|show``: the characteristics of an A2L, and one map with its values.

The A2L is parsed once and cached by content (``MAPWISE_CACHE_DIR``, bounded by
``MAPWISE_CACHE_MB`` / ``MAPWISE_CACHE_FILES``), so a second look at a large A2L is quick.
See docs/cli.md#a2l and docs/calibration.md#rest-and-cli.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.cli.errors import UsageError

if TYPE_CHECKING:
    from app.calibration.a2l import A2lFile
    from app.calibration.model import Characteristic
    from app.calibration.values import CalibrationValues

DESCRIPTION_WIDTH = 48


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("a2l", help="list an A2L's maps, show one with its values")
    commands = p.add_subparsers(dest="a2l_command", required=True)
    ls = commands.add_parser(
        "list",
        help="the A2L's characteristics (MAP, CURVE, VAL_BLK, VALUE)",
        description="List the characteristics of an A2L, searched by name and description.",
    )
    ls.add_argument("file", type=Path, help="the A2L file")
    ls.add_argument("--search", default="", metavar="Q", help="part of a name or description")
    ls.add_argument("--type", metavar="T1,T2", help="MAP, CURVE, VAL_BLK, VALUE (comma-separated)")
    ls.add_argument("--limit", type=int, default=1000, help="most characteristics shown")
    ls.add_argument("--json", action="store_true", help="print JSON")
    ls.set_defaults(handler=list_command)
    show = commands.add_parser(
        "show",
        help="one characteristic, with its current values from a HEX/S19/DCM/CDFX file",
        description="Show one characteristic of an A2L: axes, units, conversion, limits, "
        "record layout and, with --values, its current values.",
    )
    show.add_argument("file", type=Path, help="the A2L file")
    show.add_argument("--map", required=True, metavar="NAME", help="the characteristic")
    show.add_argument("--values", type=Path, metavar="FILE", help="HEX, S19, DCM or CDFX")
    show.add_argument("--json", action="store_true", help="print JSON")
    show.set_defaults(handler=show_command)


def read_file(path: Path, flag: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise UsageError(f"{flag} {path}: {exc.strerror}") from None


def open_a2l_file(path: Path) -> A2lFile:
    """The parsed A2L at ``path``, through the cache of the settings (env)."""
    from app.config import Settings
    from app.services.a2l_cache import open_bytes
    from app.services.ecus import cache_limits

    return open_bytes(read_file(path, "a2l"), cache_limits(Settings()))


def parse_types(raw: str | None) -> tuple[str, ...]:
    from app.calibration.model import CHARACTERISTIC_TYPES

    if not raw:
        return ()
    types = tuple(t.strip().upper() for t in raw.split(",") if t.strip())
    bad = [t for t in types if t not in CHARACTERISTIC_TYPES]
    if bad:
        raise UsageError(f"--type {bad[0]}: choose from {', '.join(CHARACTERISTIC_TYPES)}")
    return types


def list_command(args: argparse.Namespace) -> int:
    if args.limit < 1:
        raise UsageError(f"--limit must be at least 1, got {args.limit}")
    a2l = open_a2l_file(args.file)
    total, items = a2l.search(
        query=args.search, types=parse_types(args.type), limit=args.limit, offset=0
    )
    if args.json:
        print(json.dumps({"total": total, "items": [c.to_json() for c in items]}))
        return 0
    rows = [("NAME", "TYPE", "SHAPE", "UNIT", "DESCRIPTION")]
    for c in items:
        shape = "×".join(map(str, c.shape)) or "-"
        rows.append((c.name, c.type, shape, c.unit, c.description[:DESCRIPTION_WIDTH]))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    for r in rows:
        print("  ".join(r[i].ljust(widths[i]) for i in range(4)) + "  " + r[4])
    shown = f"{len(items)} of {total}" if len(items) < total else str(total)
    print(f"{shown} characteristic{'s' if total != 1 else ''}")
    return 0


def show_command(args: argparse.Namespace) -> int:
    from app.calibration.values import read_values

    a2l = open_a2l_file(args.file)
    char = a2l.get(args.map)
    values = None
    if args.values is not None:
        values = read_values(a2l, char, read_file(args.values, "--values"))
    if args.json:
        print(json.dumps(char_document(char, values)))
        return 0
    print(format_char(char, values))
    return 0


def char_document(char: Characteristic, values: CalibrationValues | None) -> dict[str, Any]:
    """The REST map document (``GET /api/ecus/{id}/maps/{name}``) of a characteristic."""
    from app.services.ecus import values_json

    return char.to_json() | {"values": None if values is None else values_json(values)}


def format_char(char: Characteristic, values: CalibrationValues | None) -> str:
    """A human-readable view: what the A2L says, then the values as a grid."""
    shape = "×".join(map(str, char.shape))
    facts = [
        f"unit {char.unit!r}",
        f"limits [{char.lower:g}, {char.upper:g}]",
        char.datatype,
        f"{char.compu_method.kind} ({char.compu_method.name})",
        f"layout {char.record_layout.name}",
        f"address 0x{char.address:X}",
        char.byte_order,
    ]
    lines = [
        f"{char.name} ({char.type}{' ' + shape if shape else ''})",
        f"  {char.description}" if char.description else "",
        "  " + ", ".join(f for f in facts if f),
    ]
    for letter, axis in zip("XYZ", char.axes, strict=False):
        fixed = "" if axis.fix_axis_values is None else f" = {list(axis.fix_axis_values)}"
        lines.append(
            f"  axis {letter}: {axis.input_quantity} [{axis.unit}] {axis.attribute}, "
            f"{axis.points} points{fixed}"
        )
    lines = [line for line in lines if line]
    if values is not None:
        lines.append(format_values(values))
    return "\n".join(lines)


def format_values(values: CalibrationValues) -> str:
    """Rows: the first axis; columns: the second (a curve is one column)."""
    array = np.asarray(values.values, dtype=np.float64)
    width = 10
    if array.ndim == 0:
        return f"  value {float(array):g} {values.unit}".rstrip()
    if array.ndim == 1:
        xs = values.axes[0] if values.axes else np.arange(array.size)
        return "\n".join(f"{x:>{width}g}  {v:>{width}.6g}" for x, v in zip(xs, array, strict=True))
    if array.ndim != 2 or len(values.axes) != 2:
        return f"  (a {array.ndim}-D block: use --json)"
    xs, ys = values.axes
    lines = [" " * width + "".join(f"{y:>{width}g}" for y in ys)]
    for x, row in zip(xs, array, strict=True):
        lines.append(f"{x:>{width}g}" + "".join(f"{v:>{width}.6g}" for v in row))
    return "\n".join(lines)
