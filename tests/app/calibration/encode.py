"""A hand-written encoder of the completed ASAM demo's records, independent of
:mod:`app.calibration.image`: it packs known values with :mod:`struct` exactly as the
layouts of :mod:`tests.app.calibration.demo_a2l` lay them out, and bincopy writes the
images. The decoder under test must read these values back.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import bincopy
import numpy as np

from tests.app.calibration.demo_a2l import FIX_AXIS_VALUES

# address, kind, axis points in use (None: not stored in the record), as in the demo A2L.
AXIS_PTS_UBYTE_8 = 8454976
CURVES_STD = {  # name: (address, INCR/DECR, points in use, max points)
    "ASAM.C.CURVE.STD_AXIS": (8454912, "DECR", 6, 8),
    "ASAM.C.CURVE.STD_AXIS.MONOTONY_STRICT_INCREASE": (8456192, "DECR", 8, 8),
    "ASAM.C.CURVE.STD_AXIS.MONOTONY_STRICT_DECREASE": (8456224, "DECR", 5, 8),
    "ASAM.C.CURVE_AXIS": (8455056, "INCR", 4, 8),  # 14 bytes: RES_AXIS follows at +16
}
CURVES_FNC = {  # name: (address, number of values); axis points from the A2L / AXIS_PTS
    "ASAM.C.CURVE.COM_AXIS": (8454944, 8),
    "ASAM.C.CURVE.FIX_AXIS.PAR_DIST": (8454992, 6),
    "ASAM.C.CURVE.FIX_AXIS.PAR": (8455008, 6),
    "ASAM.C.CURVE.FIX_AXIS.PAR_LIST": (8455024, 6),
    "ASAM.C.CURVE.CURVE_AXIS": (8455040, 8),
    "ASAM.C.CURVE.RES_AXIS": (8455072, 9),
}
MAP_STD = ("ASAM.C.MAP.STD_AXIS.STD_AXIS", 8455168)  # RL.MAP.SWORD.SBYTE.SBYTE.INCR
MAP_COM_FIX = ("ASAM.C.MAP.COM_AXIS.FIX_AXIS", 8455232)  # RL.FNC.SWORD.ROW_DIR, 8 x 3
COMMON_AXIS = np.array([-90.0, -60.0, -30.0, -5.0, 0.0, 20.0, 70.0, 120.0])


@dataclass
class Known:
    """Values encoded for one characteristic and where its record lies."""

    axes: tuple[np.ndarray, ...]
    values: np.ndarray
    address: int
    size: int


def known_values(order: str = "<", seed: int = 0) -> tuple[dict[str, Known], dict[int, bytes]]:
    """``(known values by name, {address: record bytes})`` for every MAP and CURVE of the
    completed demo, in byte order ``order`` (``"<"`` MSB_LAST, ``">"`` MSB_FIRST)."""
    rng = np.random.default_rng(seed)
    known: dict[str, Known] = {}
    records: dict[int, bytes] = {}

    def sword(n: int) -> np.ndarray:
        return rng.integers(-32268, 32268, size=n).astype(np.float64)

    for name, (address, index, n, _max) in CURVES_STD.items():
        axis = np.sort(rng.choice(np.arange(-128, 128), size=n, replace=False)).astype(float)
        values = sword(n)
        stored_axis = axis[::-1] if index == "DECR" else axis
        head = struct.pack("B", n) + struct.pack(f"{n}b", *stored_axis.astype(int))
        head += b"\0" * ((address + len(head)) % 2)  # SWORD alignment 2
        record = head + struct.pack(f"{order}{n}h", *values.astype(int))
        known[name] = Known((axis,), values, address, len(record))
        records[address] = record

    # COM_AXIS points: RL.AXIS_PTS.SBYTE.DECR (count byte, then points in reverse order).
    records[AXIS_PTS_UBYTE_8] = struct.pack("B", 8) + struct.pack(
        "8b", *COMMON_AXIS[::-1].astype(int)
    )
    fix_3 = np.array([0.0, 1.0, 2.0])  # FIX_AXIS_PAR_DIST 0 1 3 (demo_a2l default)
    for name, (address, n) in CURVES_FNC.items():
        values = sword(n)
        if name in FIX_AXIS_VALUES:
            axis = np.array(FIX_AXIS_VALUES[name])
        elif name == "ASAM.C.CURVE.COM_AXIS":
            axis = COMMON_AXIS
        else:  # CURVE_AXIS / RES_AXIS: point indices
            axis = np.arange(n, dtype=float)
        record = struct.pack(f"{order}{n}h", *values.astype(int))
        known[name] = Known((axis,), values, address, len(record))
        records[address] = record

    name, address = MAP_STD
    nx, ny = 3, 5  # in use (max 4 and 5)
    x = np.array([-100.0, 0.0, 100.0])
    y = np.array([0.0, 1.0, 2.0, 3.0, 4.0])  # TAB_VERB axis: raw = phys
    values = sword(nx * ny).reshape(nx, ny)
    head = struct.pack("BB", nx, ny) + struct.pack(f"{nx}b", *x.astype(int))
    head += struct.pack(f"{ny}b", *y.astype(int))
    head += b"\0" * ((address + len(head)) % 2)
    # COLUMN_DIR: X fastest.
    body = [int(values[i, j]) for j in range(ny) for i in range(nx)]
    record = head + struct.pack(f"{order}{nx * ny}h", *body)
    known[name] = Known((x, y), values, address, len(record))
    records[address] = record

    name, address = MAP_COM_FIX
    values = sword(8 * 3).reshape(8, 3)
    body = [int(values[i, j]) for i in range(8) for j in range(3)]  # ROW_DIR: Y fastest
    record = struct.pack(f"{order}24h", *body)
    known[name] = Known((COMMON_AXIS, fix_3), values, address, len(record))
    records[address] = record
    return known, records


def image(records: dict[int, bytes], fmt: str, *, bytes_per_line: int = 16) -> bytes:
    """The records as an Intel HEX (``"hex"``) or S-record (``"s19"``) file by bincopy."""
    binfile = bincopy.BinFile()
    for address, data in sorted(records.items()):
        binfile.add_binary(data, address=address)
    if fmt == "hex":
        return binfile.as_ihex(number_of_data_bytes=bytes_per_line).encode("ascii")
    return binfile.as_srec(number_of_data_bytes=bytes_per_line, address_length_bits=32).encode(
        "ascii"
    )


def memory(data: bytes, fmt: str) -> dict[int, int]:
    """Every byte of an image by address (via bincopy)."""
    binfile = bincopy.BinFile()
    text = data.decode("ascii")
    binfile.add_ihex(text) if fmt == "hex" else binfile.add_srec(text)
    out: dict[int, int] = {}
    for segment in binfile.segments:
        for offset, byte in enumerate(segment.data):
            out[segment.minimum_address + offset] = byte
    return out
