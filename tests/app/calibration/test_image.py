"""Values of every MAP and CURVE of the ASAM demo A2L decoded from HEX and S19 images that a
hand-written encoder (tests/app/calibration/encode.py) and bincopy build, and patched
images that differ from the original only in the map's bytes."""

from __future__ import annotations

import struct
from pathlib import Path

import bincopy
import numpy as np
import pytest

from app.calibration.a2l import A2lFile, open_a2l
from app.calibration.image import decode_image, patch_image
from app.calibration.values import CalibrationValues
from app.io.errors import InputError
from tests.app.calibration.demo_a2l import full_demo_text
from tests.app.calibration.encode import (
    AXIS_PTS_UBYTE_8,
    COMMON_AXIS,
    MAP_STD,
    image,
    known_values,
    memory,
)

FORMATS = ("hex", "s19")


@pytest.fixture(scope="module")
def big_endian_a2l(shared_a2l_cache: Path) -> A2lFile:
    """The completed demo with ``BYTE_ORDER MSB_FIRST`` in MOD_COMMON."""
    text = full_demo_text().replace("MSB_LAST  /* byteOrder */", "MSB_FIRST  /* byteOrder */")
    assert "MSB_FIRST  /* byteOrder */" in text
    return open_a2l(text.encode("latin-1"), cache_dir=shared_a2l_cache)


def test_the_encoder_covers_every_map_and_curve_of_the_demo(full_demo_a2l: A2lFile) -> None:
    known, _ = known_values()
    listed = {c.name for c in full_demo_a2l.characteristics if c.type in ("MAP", "CURVE")}
    assert listed == set(known)
    assert len(listed) == 12  # 10 CURVEs, 2 MAPs


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_map_and_curve_decodes_to_the_encoded_values(
    full_demo_a2l: A2lFile, fmt: str
) -> None:
    known, records = known_values()
    data = image(records, fmt)
    for name, want in known.items():
        got = decode_image(full_demo_a2l, full_demo_a2l.get(name), data)
        assert got.name == name
        assert got.values.shape == want.values.shape, name
        np.testing.assert_array_equal(got.values, want.values, err_msg=name)
        assert len(got.axes) == len(want.axes)
        for got_axis, want_axis in zip(got.axes, want.axes, strict=True):
            np.testing.assert_array_equal(got_axis, want_axis, err_msg=name)


@pytest.mark.slow
def test_big_endian_images_decode_with_msb_first(big_endian_a2l: A2lFile) -> None:
    known, records = known_values(order=">", seed=3)
    data = image(records, "hex")
    assert big_endian_a2l.get(MAP_STD[0]).byte_order == "MSB_FIRST"
    for name, want in known.items():
        got = decode_image(big_endian_a2l, big_endian_a2l.get(name), data)
        np.testing.assert_array_equal(got.values, want.values, err_msg=name)


def test_units_and_axis_names_come_from_the_a2l(full_demo_a2l: A2lFile) -> None:
    _, records = known_values()
    char = full_demo_a2l.get("ASAM.C.MAP.STD_AXIS.STD_AXIS")
    got = decode_image(full_demo_a2l, char, image(records, "hex"))
    assert got.unit == char.unit == "hours"
    assert got.axis_names == (
        "ASAM.M.SCALAR.SBYTE.IDENTICAL",
        "ASAM.M.SCALAR.UBYTE.TAB_VERB_NO_DEFAULT_VALUE",
    )
    assert got.axis_categories == ("STD_AXIS", "STD_AXIS")


@pytest.mark.parametrize("fmt", FORMATS)
def test_patching_unchanged_values_gives_the_identical_file(
    full_demo_a2l: A2lFile, fmt: str
) -> None:
    known, records = known_values()
    data = image(records, fmt)
    for name in known:
        char = full_demo_a2l.get(name)
        patched = patch_image(full_demo_a2l, char, decode_image(full_demo_a2l, char, data), data)
        assert patched == data, name
        assert memory(patched, fmt) == memory(data, fmt)


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("name", ["ASAM.C.MAP.STD_AXIS.STD_AXIS", "ASAM.C.MAP.COM_AXIS.FIX_AXIS"])
def test_a_changed_map_changes_only_its_own_bytes(
    full_demo_a2l: A2lFile, fmt: str, name: str
) -> None:
    known, records = known_values()
    data = image(records, fmt, bytes_per_line=32)
    char = full_demo_a2l.get(name)
    current = decode_image(full_demo_a2l, char, data)
    new_values = current.values + np.arange(current.values.size).reshape(current.values.shape)
    new_values[0, 0] = -1234.0
    changed = CalibrationValues(name, current.axes, new_values, current.unit)

    patched = patch_image(full_demo_a2l, char, changed, data)

    before, after = memory(data, fmt), memory(patched, fmt)
    assert before.keys() == after.keys()
    diff = sorted(a for a in before if before[a] != after[a])
    start, size = known[name].address, known[name].size
    assert diff, "the map's bytes must change"
    assert all(start <= a < start + size for a in diff), [hex(a) for a in diff[:5]]
    np.testing.assert_array_equal(decode_image(full_demo_a2l, char, patched).values, new_values)
    # Every other map still decodes to its old values.
    for other, want in known.items():
        if other != name:
            got = decode_image(full_demo_a2l, full_demo_a2l.get(other), patched)
            np.testing.assert_array_equal(got.values, want.values, err_msg=other)


@pytest.mark.parametrize("fmt", FORMATS)
def test_patched_lines_keep_their_length_and_record_type(full_demo_a2l: A2lFile, fmt: str) -> None:
    _, records = known_values()
    data = image(records, fmt, bytes_per_line=20)
    char = full_demo_a2l.get("ASAM.C.CURVE.STD_AXIS")
    current = decode_image(full_demo_a2l, char, data)
    changed = CalibrationValues(char.name, current.axes, current.values // 2 + 7, "")

    patched = patch_image(full_demo_a2l, char, changed, data)

    old_lines, new_lines = data.splitlines(), patched.splitlines()
    assert len(old_lines) == len(new_lines)
    differing = [(a, b) for a, b in zip(old_lines, new_lines, strict=True) if a != b]
    assert differing
    for old, new in differing:
        assert len(old) == len(new)
        assert old[:3] == new[:3] if fmt == "s19" else old[7:9] == new[7:9]
    # bincopy verifies every record's checksum while reading the patched file.
    check = bincopy.BinFile()
    text = patched.decode("ascii")
    check.add_ihex(text) if fmt == "hex" else check.add_srec(text)


def test_patch_rewrites_std_axis_points_in_the_record(full_demo_a2l: A2lFile) -> None:
    _, records = known_values()
    data = image(records, "hex")
    char = full_demo_a2l.get("ASAM.C.CURVE.STD_AXIS")
    current = decode_image(full_demo_a2l, char, data)
    moved = current.axes[0] + np.array([0, 1, 1, 1, 1, 2])

    patched = patch_image(
        full_demo_a2l, char, CalibrationValues(char.name, (moved,), current.values), data
    )

    np.testing.assert_array_equal(decode_image(full_demo_a2l, char, patched).axes[0], moved)


def test_patch_refuses_to_move_a_shared_common_axis(full_demo_a2l: A2lFile) -> None:
    _, records = known_values()
    data = image(records, "hex")
    char = full_demo_a2l.get("ASAM.C.CURVE.COM_AXIS")
    current = decode_image(full_demo_a2l, char, data)
    moved = CalibrationValues(char.name, (current.axes[0] + 1,), current.values)
    with pytest.raises(InputError, match=r"ASAM\.C\.CURVE\.COM_AXIS: axis X .* COM_AXIS"):
        patch_image(full_demo_a2l, char, moved, data)


def test_patch_refuses_a_different_shape(full_demo_a2l: A2lFile) -> None:
    _, records = known_values()
    data = image(records, "hex")
    char = full_demo_a2l.get("ASAM.C.MAP.STD_AXIS.STD_AXIS")
    current = decode_image(full_demo_a2l, char, data)
    wrong = CalibrationValues(char.name, current.axes, current.values[:2])
    with pytest.raises(InputError, match=r"STD_AXIS\.STD_AXIS: values have shape \(2, 5\)"):
        patch_image(full_demo_a2l, char, wrong, data)


def test_an_image_without_the_map_names_the_characteristic_and_range(
    full_demo_a2l: A2lFile,
) -> None:
    _, records = known_values()
    name, address = MAP_STD
    del records[address]
    records[address] = b"\x03\x05\x9c\x00\x64"  # only the counts and the first X points
    data = image(records, "hex")
    with pytest.raises(InputError, match=name.replace(".", r"\.")) as error:
        decode_image(full_demo_a2l, full_demo_a2l.get(name), data)
    assert f"0x{address + 5:X}" in str(error.value)
    assert error.value.field == "values"
    with pytest.raises(InputError, match="does not cover"):
        patch_image(
            full_demo_a2l,
            full_demo_a2l.get(name),
            CalibrationValues(name, (np.zeros(3), np.zeros(5)), np.zeros((3, 5))),
            data,
        )


def test_a_common_axis_outside_the_image_is_named(full_demo_a2l: A2lFile) -> None:
    _, records = known_values()
    del records[AXIS_PTS_UBYTE_8]
    with pytest.raises(InputError, match=r"ASAM\.C\.CURVE\.COM_AXIS.*AXIS_PTS.*does not cover"):
        decode_image(
            full_demo_a2l, full_demo_a2l.get("ASAM.C.CURVE.COM_AXIS"), image(records, "s19")
        )


def test_a_stored_point_count_beyond_the_a2l_maximum_is_refused(full_demo_a2l: A2lFile) -> None:
    _, records = known_values()
    records[AXIS_PTS_UBYTE_8] = struct.pack("B", 9) + bytes(9)
    with pytest.raises(InputError, match=r"stores 9 points for axis X.*1–8"):
        decode_image(
            full_demo_a2l, full_demo_a2l.get("ASAM.C.CURVE.COM_AXIS"), image(records, "hex")
        )


def test_the_stripped_demo_has_no_record_layouts_to_decode_with(demo_a2l: A2lFile) -> None:
    _, records = known_values()
    with pytest.raises(
        InputError, match=r"RECORD_LAYOUT 'RL\.MAP\.SWORD\.SBYTE\.SBYTE\.INCR' is not"
    ):
        decode_image(demo_a2l, demo_a2l.get(MAP_STD[0]), image(records, "hex"))


@pytest.mark.slow
def test_a_fix_axis_without_parameters_is_refused(demo_a2l_bytes: bytes, tmp_path: Path) -> None:
    # The stripped demo, completed with RECORD_LAYOUTs only (no FIX_AXIS_PAR*).
    full = full_demo_text()
    layouts = full[full.index("    /begin RECORD_LAYOUT") : full.index("    /begin MOD_COMMON")]
    text = demo_a2l_bytes.decode("latin-1").replace("\r\n", "\n")
    text = text.replace("    /begin MOD_COMMON", layouts + "    /begin MOD_COMMON", 1)
    a2l = open_a2l(text.encode("latin-1"), cache_dir=tmp_path)
    _, records = known_values()
    with pytest.raises(InputError, match=r"PAR_DIST: axis X .* FIX_AXIS without FIX_AXIS_PAR"):
        decode_image(a2l, a2l.get("ASAM.C.CURVE.FIX_AXIS.PAR_DIST"), image(records, "hex"))


@pytest.mark.parametrize(
    "data",
    [b":10000000ZZ\n", b":0400000001020304F0\n:00000001FF\n", b"S1130000000102\n"],
    ids=["bad-hex-digits", "bad-checksum", "short-srec"],
)
def test_a_corrupt_image_is_refused(full_demo_a2l: A2lFile, data: bytes) -> None:
    with pytest.raises(InputError, match="image is corrupt") as error:
        decode_image(full_demo_a2l, full_demo_a2l.get(MAP_STD[0]), data)
    assert error.value.field == "values"


def test_values_and_blocks_decode_with_their_datatypes_and_conversions(
    full_demo_a2l: A2lFile,
) -> None:
    """VALUEs of several data types and conversions, and VAL_BLKs in both index modes."""
    records = {
        8454144: struct.pack("<B", 150),  # UBYTE.IDENTICAL
        8454146: struct.pack("<H", 0x1234),  # UWORD (BIT_MASK 0x0FF0 → 0x23)
        8454148: struct.pack("<h", -1234),  # SWORD: LINEAR_MUL_2, RAT_FUNC_DIV_10, …
        8454152: struct.pack("<I", 1_500_000),  # ULONG
        8454160: struct.pack("<f", 123.25),  # FLOAT32
        8454400: struct.pack("<12h", *range(12)),  # 3x4 ROW_DIR
        8454432: struct.pack("<12h", *range(12)),  # 3x4 COLUMN_DIR
    }
    data = image(records, "hex")
    expect = {
        "ASAM.C.SCALAR.UBYTE.IDENTICAL": 150.0,
        "ASAM.C.SCALAR.UWORD.IDENTICAL.BITMASK_0FF0": 0x23,
        "ASAM.C.SCALAR.SWORD.LINEAR_MUL_2": -2468.0,
        "ASAM.C.SCALAR.SWORD.RAT_FUNC_DIV_10": -123.4,
        "ASAM.C.SCALAR.ULONG.IDENTICAL": 1_500_000.0,
        "ASAM.C.SCALAR.FLOAT32_IEEE.IDENTICAL": 123.25,
        "ASAM.C.SCALAR.SWORD.TAB_INTP_NO_DEFAULT_VALUE": 0.0,  # below the table: held
    }
    for name, value in expect.items():
        got = decode_image(full_demo_a2l, full_demo_a2l.get(name), data)
        assert got.values.shape == ()
        assert got.values == pytest.approx(value, rel=1e-12), name
    row = decode_image(
        full_demo_a2l, full_demo_a2l.get("ASAM.C.ARRAY.SWORD.MATRIX_DIM_3_4.ROW_DIR"), data
    )
    col = decode_image(
        full_demo_a2l, full_demo_a2l.get("ASAM.C.ARRAY.SWORD.MATRIX_DIM_3_4.COLUMN_DIR"), data
    )
    np.testing.assert_array_equal(row.values, np.arange(12).reshape(3, 4))
    np.testing.assert_array_equal(col.values, np.arange(12).reshape(3, 4, order="F"))
    assert row.axes == ()


def test_patching_a_bit_masked_value_keeps_the_other_bits(full_demo_a2l: A2lFile) -> None:
    data = image({8454146: struct.pack("<H", 0x1234)}, "s19")
    char = full_demo_a2l.get("ASAM.C.SCALAR.UWORD.IDENTICAL.BITMASK_0FF0")
    patched = patch_image(
        full_demo_a2l, char, CalibrationValues(char.name, (), np.array(0xAB)), data
    )
    assert memory(patched, "s19")[8454146] == 0xB4  # low byte: 0x_4 kept, 0xB_ new
    assert memory(patched, "s19")[8454147] == 0x1A
    assert float(decode_image(full_demo_a2l, char, patched).values) == 0xAB


def test_common_axis_values(full_demo_a2l: A2lFile) -> None:
    _, records = known_values()
    got = decode_image(
        full_demo_a2l, full_demo_a2l.get("ASAM.C.MAP.COM_AXIS.FIX_AXIS"), image(records, "hex")
    )
    np.testing.assert_array_equal(got.axes[0], COMMON_AXIS)
    np.testing.assert_array_equal(got.axes[1], [0.0, 1.0, 2.0])


def test_line_ends_and_letter_case_of_the_file_are_kept(full_demo_a2l: A2lFile) -> None:
    _, records = known_values()
    data = image(records, "hex").decode().lower().replace("\n", "\r\n").encode()
    char = full_demo_a2l.get("ASAM.C.CURVE.FIX_AXIS.PAR")
    current = decode_image(full_demo_a2l, char, data)
    changed = CalibrationValues(char.name, current.axes, current.values + 1)

    patched = patch_image(full_demo_a2l, char, changed, data)

    assert patched != data
    assert patched == patched.lower()
    assert patched.count(b"\r\n") == data.count(b"\r\n")
    np.testing.assert_array_equal(
        decode_image(full_demo_a2l, char, patched).values, current.values + 1
    )
