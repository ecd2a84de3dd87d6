"""The files of the ECU walk-through (tests/frontend/test_ecu.py, scripts/ecu_screenshot.py):
the ASAM demo A2L from the pya2ldb wheel completed by ``tests.app.calibration.demo_a2l``, an
Intel HEX image written with ``bincopy`` that holds known values of one demo MAP, and a
drive log whose columns carry that map's input quantities (one with a tool suffix).

The record of ``ASAM.C.MAP.STD_AXIS.STD_AXIS`` (layout ``RL.MAP.SWORD.SBYTE.SBYTE.INCR``,
docs/calibration.md#values): ``NO_AXIS_PTS_X`` and ``NO_AXIS_PTS_Y``
(UBYTE), the X then Y axis points (SBYTE, ascending), one byte of padding to the WORD
border, then the values (SWORD, ``COLUMN_DIR``: X fastest), all little-endian (the demo's
``BYTE_ORDER MSB_LAST``) from address 0x810400.
"""

from __future__ import annotations

import struct
from pathlib import Path

import bincopy
import numpy as np

from tests.app.calibration.demo_a2l import full_demo_text

MAP_NAME = "ASAM.C.MAP.STD_AXIS.STD_AXIS"
MAP_ADDRESS = 0x810400
MAP_UNIT = "hours"  # CM.IDENTICAL's unit in the demo
X_QUANTITY = "ASAM.M.SCALAR.SBYTE.IDENTICAL"
Y_QUANTITY = "ASAM.M.SCALAR.UBYTE.TAB_VERB_NO_DEFAULT_VALUE"
X_POINTS = (-10, 0, 10, 20)
Y_POINTS = (0, 1, 2, 3, 4)
#: values[i_x][i_y] as stored: 100 + 10·i_x + 3·i_y hours
VALUES = tuple(tuple(100 + 10 * i + 3 * j for j in range(len(Y_POINTS))) for i in range(4))
#: the logged X column: the quantity with INCA's suffix (matched by name, suffix ignored)
X_CHANNEL = X_QUANTITY + "\\ETK:1"
OUTPUT = "runtime"


def map_record() -> bytes:
    """The MAP's record as the ECU stores it."""
    head = struct.pack("<BB", len(X_POINTS), len(Y_POINTS))
    axes = struct.pack(f"<{len(X_POINTS)}b{len(Y_POINTS)}b", *X_POINTS, *Y_POINTS)
    pad = b"\x00" * ((len(head) + len(axes)) % 2)
    column_dir = [VALUES[i][j] for j in range(len(Y_POINTS)) for i in range(len(X_POINTS))]
    return head + axes + pad + struct.pack(f"<{len(column_dir)}h", *column_dir)


def write_files(folder: Path) -> tuple[Path, Path, Path]:
    """The A2L, the HEX image and the drive log (CSV) in ``folder``."""
    a2l = folder / "ASAP2_Demo_V161.a2l"
    a2l.write_text(full_demo_text(), encoding="latin-1")
    image = bincopy.BinFile()
    image.add_binary(map_record(), address=MAP_ADDRESS)
    hex_path = folder / "demo_ecu.hex"
    hex_path.write_text(image.as_ihex())
    csv = folder / "demo_drive.csv"
    csv.write_text(drive_log())
    return a2l, hex_path, csv


def memory(image: bytes) -> dict[int, int]:
    """The bytes of an Intel HEX image by address (to compare an image before and after)."""
    binfile = bincopy.BinFile()
    binfile.add_ihex(image.decode())
    return {
        segment.minimum_address + i: byte
        for segment in binfile.segments
        for i, byte in enumerate(segment.data)
    }


def drive_log(
    rate_hz: float = 50.0, duration_s: float = 60.0, seed: int = 3, y_column: str = Y_QUANTITY
) -> str:
    """A log sweeping the map's operating range; the measured output is the stored map
    plus 15 hours everywhere, with noise, so the adapted map moves off the stored one. The Y
    quantity is logged as ``y_column``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    x = 5.0 + 14.0 * np.sin(2 * np.pi * t / 17.0)
    y = 2.0 + 1.9 * np.sin(2 * np.pi * t / 7.3 + 0.4)
    true = np.array(VALUES, dtype=float) + 15.0
    out = np.array([bilinear(true, xi, yi) for xi, yi in zip(x, y, strict=True)])
    out += rng.normal(0.0, 0.5, size=out.shape)
    rows = [f"time [s],{X_CHANNEL},{y_column},{OUTPUT} [{MAP_UNIT}]"]
    rows += [f"{a:.2f},{b:.3f},{c:.3f},{d:.3f}" for a, b, c, d in zip(t, x, y, out, strict=True)]
    return "\n".join(rows) + "\n"


def bilinear(values: np.ndarray, x: float, y: float) -> float:
    """The table's value at (x, y), clamped to its grid."""
    xs = np.asarray(X_POINTS, dtype=float)
    ys = np.asarray(Y_POINTS, dtype=float)
    i = int(np.clip(np.searchsorted(xs, x) - 1, 0, len(xs) - 2))
    j = int(np.clip(np.searchsorted(ys, y) - 1, 0, len(ys) - 2))
    u = float(np.clip((x - xs[i]) / (xs[i + 1] - xs[i]), 0.0, 1.0))
    v = float(np.clip((y - ys[j]) / (ys[j + 1] - ys[j]), 0.0, 1.0))
    return float(
        (1 - u) * (1 - v) * values[i, j]
        + u * (1 - v) * values[i + 1, j]
        + (1 - u) * v * values[i, j + 1]
        + u * v * values[i + 1, j + 1]
    )
