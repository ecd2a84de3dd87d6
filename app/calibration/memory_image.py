"""The bytes of an Intel HEX or Motorola S-record memory image: read by address, and
patched in place.

:class:`Memory` merges the image's data records into contiguous segments (bincopy) and
reads a byte range, naming the first address no segment covers. :func:`write_patches`
rewrites only the data records that hold changed bytes: every other line of the file stays
as it was, and the changed lines keep their length, record type and letter case (only their
data and checksum change). The characteristic records inside an image are
:mod:`app.calibration.image`'s.
"""

from __future__ import annotations

import bincopy

from app.calibration.values import detect_values_format
from app.io.errors import InputError


class Memory:
    """The bytes of a HEX/S19 image by address (contiguous segments merged by bincopy)."""

    def __init__(self, image: bytes, owner: str) -> None:
        self.format = detect_values_format(image)
        if self.format not in ("hex", "s19"):
            raise InputError(
                f"characteristic {owner}: values are a {self.format.upper()} file, "
                "not a HEX/S19 memory image",
                field="values",
            )
        binfile = bincopy.BinFile()
        try:
            text = image.decode("ascii")
            if self.format == "hex":
                binfile.add_ihex(text)
            else:
                binfile.add_srec(text)
        except (bincopy.Error, UnicodeDecodeError, ValueError) as exc:
            raise InputError(
                f"the {self.format.upper()} image is corrupt: {exc}", field="values"
            ) from None
        self.segments = [(s.minimum_address, bytes(s.data)) for s in binfile.segments]

    def read(self, address: int, size: int, what: str) -> bytes:
        for start, data in self.segments:
            if start <= address and address + size <= start + len(data):
                return data[address - start : address - start + size]
        raise InputError(
            f"{what}: the image does not cover {_missing(self.segments, address, size)} "
            f"(needed: 0x{address:X}–0x{address + size - 1:X}, {size} bytes)",
            field="values",
        )


def _missing(segments: list[tuple[int, bytes]], address: int, size: int) -> str:
    """The first address range of ``[address, address+size)`` no segment covers."""
    covered = sorted((s, s + len(d)) for s, d in segments)
    cursor, end = address, address + size
    for start, stop in covered:
        if stop <= cursor:
            continue
        if start > cursor:
            return f"0x{cursor:X}–0x{min(start, end) - 1:X}"
        cursor = stop
        if cursor >= end:
            break
    return f"0x{cursor:X}–0x{end - 1:X}"


def write_patches(image: bytes, fmt: str, patches: list[tuple[int, bytes]]) -> bytes:
    """``image`` with each ``(address, bytes)`` written into its data records in place."""
    changes: dict[int, int] = {}
    for address, data in patches:
        for offset, byte in enumerate(data):
            changes[address + offset] = byte
    lines = image.decode("ascii").splitlines(keepends=True)
    patch_line = _patch_ihex_line if fmt == "hex" else _patch_srec_line
    state = {"base": 0, "low": min(changes, default=0), "high": max(changes, default=-1)}
    out = [patch_line(line, changes, state) for line in lines]
    return "".join(out).encode("ascii")


def _patch_ihex_line(line: str, changes: dict[int, int], state: dict[str, int]) -> str:
    body = line.rstrip("\r\n")
    if not body.startswith(":"):
        return line
    record = bytearray.fromhex(body[1:])
    count, offset, kind = record[0], int.from_bytes(record[1:3], "big"), record[3]
    if kind == 0x02:
        state["base"] = int.from_bytes(record[4:6], "big") << 4
    elif kind == 0x04:
        state["base"] = int.from_bytes(record[4:6], "big") << 16
    if kind != 0x00:
        return line
    start = state["base"] + offset
    if not _overlaps(changes, start, count, state):
        return line
    for i in range(count):
        record[4 + i] = changes.get(start + i, record[4 + i])
    record[-1] = (-sum(record[:-1])) & 0xFF
    return ":" + _hex_like(record, body[1:]) + line[len(body) :]


def _patch_srec_line(line: str, changes: dict[int, int], state: dict[str, int]) -> str:
    body = line.rstrip("\r\n")
    if len(body) < 2 or body[0] != "S" or body[1] not in "123":
        return line
    width = {"1": 2, "2": 3, "3": 4}[body[1]]
    record = bytearray.fromhex(body[2:])
    start = int.from_bytes(record[1 : 1 + width], "big")
    data_from = 1 + width
    count = len(record) - data_from - 1
    if not _overlaps(changes, start, count, state):
        return line
    for i in range(count):
        record[data_from + i] = changes.get(start + i, record[data_from + i])
    record[-1] = 0xFF - (sum(record[:-1]) & 0xFF)
    return body[:2] + _hex_like(record, body[2:]) + line[len(body) :]


def _hex_like(record: bytearray, original: str) -> str:
    """Hex digits of ``record`` in the letter case of the line they replace."""
    digits = record.hex()
    return (
        digits if original == original.lower() and original != original.upper() else digits.upper()
    )


def _overlaps(changes: dict[int, int], start: int, count: int, state: dict[str, int]) -> bool:
    if start > state["high"] or start + count <= state["low"]:
        return False
    return any(start + i in changes for i in range(count))
