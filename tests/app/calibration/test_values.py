"""A characteristic's current values from HEX, S19, DCM and CDFX, checked against the A2L."""

from __future__ import annotations

import re

import numpy as np
import pytest

from app.calibration.a2l import A2lFile
from app.calibration.cdfx import read_cdfx, write_cdfx
from app.calibration.image import decode_image, patch_image
from app.calibration.values import (
    CalibrationValues,
    check_limits,
    detect_values_format,
    learned_values,
    read_dcm_values,
    read_values,
    write_dcm,
)
from app.io.dcm import map_from_dcm
from app.io.errors import InputError
from tests.app.calibration.encode import CURVES_FNC, MAP_STD, image, known_values

MAP = MAP_STD[0]
FIX_CURVE = "ASAM.C.CURVE.FIX_AXIS.PAR_DIST"


@pytest.fixture(scope="module")
def hex_image() -> bytes:
    return image(known_values()[1], "hex")


def test_formats_are_detected_from_content(hex_image: bytes) -> None:
    assert detect_values_format(hex_image) == "hex"
    assert detect_values_format(image(known_values()[1], "s19")) == "s19"
    assert detect_values_format(b"\xef\xbb\xbfKONSERVIERUNG_FORMAT 2.0\n") == "dcm"
    assert detect_values_format(b"* comment\nKENNLINIE k 2\n") == "dcm"
    assert detect_values_format(b'<?xml version="1.0"?><MSRSW/>') == "cdfx"
    with pytest.raises(InputError, match="not Intel HEX, Motorola S-record, DCM or CDFX") as error:
        detect_values_format(b"\x89PNG\r\n")
    assert error.value.status == 415


@pytest.mark.parametrize("fmt", ["hex", "s19", "dcm", "cdfx"])
def test_every_format_gives_the_same_values(full_demo_a2l: A2lFile, fmt: str) -> None:
    known, records = known_values()
    items = []
    for name in known:
        char = full_demo_a2l.get(name)
        items.append((char, read_values(full_demo_a2l, char, image(records, "hex"))))
    files = {
        "hex": image(records, "hex"),
        "s19": image(records, "s19"),
        "dcm": write_dcm(items).encode("latin-1"),
        "cdfx": write_cdfx(items),
    }
    for name, want in known.items():
        got = read_values(full_demo_a2l, full_demo_a2l.get(name), files[fmt])
        np.testing.assert_array_equal(got.values, want.values, err_msg=f"{fmt} {name}")
        for a, b in zip(got.axes, want.axes, strict=True):
            np.testing.assert_array_equal(a, b, err_msg=f"{fmt} {name}")
        assert got.axis_names == tuple(a.input_quantity for a in full_demo_a2l.get(name).axes)


def test_dcm_is_keyed_by_the_a2l_names(full_demo_a2l: A2lFile, hex_image: bytes) -> None:
    char = full_demo_a2l.get(MAP)
    text = write_dcm([(char, read_values(full_demo_a2l, char, hex_image))])
    assert f"KENNFELD {MAP} 3 5" in text
    assert "*SSTX\tASAM.M.SCALAR.SBYTE.IDENTICAL" in text
    name, unit, table = map_from_dcm(text)
    assert (name, unit) == (MAP, "hours")
    assert table.axes[0].name == "ASAM.M.SCALAR.SBYTE.IDENTICAL"


def _dcm_curve(name: str, x: list[float], values: list[float]) -> bytes:
    curve = CalibrationValues(name, (np.array(x),), np.array(values))
    return write_dcm([(None, curve)]).encode()


def test_a_dcm_axis_with_a_different_point_count_is_refused(full_demo_a2l: A2lFile) -> None:
    data = _dcm_curve(FIX_CURVE, [0, 20, 40, 60, 80], [1, 2, 3, 4, 5])
    with pytest.raises(InputError, match=r"PAR_DIST: axis X \(.*\) has 5 points, the A2L") as e:
        read_values(full_demo_a2l, full_demo_a2l.get(FIX_CURVE), data)
    assert "FIX_AXIS has 6" in str(e.value)
    assert e.value.field == "values"


def test_a_dcm_fix_axis_with_other_points_is_refused(full_demo_a2l: A2lFile) -> None:
    data = _dcm_curve(FIX_CURVE, [0, 20, 40, 60, 80, 120], [1, 2, 3, 4, 5, 6])
    with pytest.raises(InputError, match=r"PAR_DIST: axis X .* differ from the A2L FIX_AXIS"):
        read_values(full_demo_a2l, full_demo_a2l.get(FIX_CURVE), data)


def test_a_std_axis_with_more_points_than_the_a2l_allows_is_refused(
    full_demo_a2l: A2lFile,
) -> None:
    name = "ASAM.C.CURVE.STD_AXIS"  # max 8 points
    data = _dcm_curve(name, list(range(9)), [0.0] * 9)
    with pytest.raises(InputError, match=r"STD_AXIS: axis X .* 9 points, the A2L allows at most 8"):
        read_values(full_demo_a2l, full_demo_a2l.get(name), data)


def test_a_curve_given_for_a_map_is_refused(full_demo_a2l: A2lFile) -> None:
    data = _dcm_curve(MAP, [0, 1, 2], [0, 0, 0])
    with pytest.raises(InputError, match=r"STD_AXIS\.STD_AXIS: 1 axes, the A2L MAP has 2"):
        read_values(full_demo_a2l, full_demo_a2l.get(MAP), data)


def test_a_file_without_the_characteristic_names_it(full_demo_a2l: A2lFile) -> None:
    data = _dcm_curve("OTHER.CURVE", [0, 1], [0, 0])
    with pytest.raises(InputError, match=r"no characteristic 'ASAM\.C\.MAP.*'OTHER\.CURVE'"):
        read_values(full_demo_a2l, full_demo_a2l.get(MAP), data)


def test_read_dcm_values_keeps_descriptions_units_and_axis_names() -> None:
    text = (
        "KONSERVIERUNG_FORMAT 2.0\n"
        'KENNLINIE K.L 2\n   LANGNAME "a curve"\n   EINHEIT_X "rpm"\n   EINHEIT_W "Nm"\n'
        "*SSTX\tnmot\n   ST/X 1.0 2.0\n   WERT 3.0 4.0\nEND\n"
    )
    vals = read_dcm_values(text)["K.L"]
    assert (vals.description, vals.unit, vals.axis_units, vals.axis_names) == (
        "a curve",
        "Nm",
        ("rpm",),
        ("nmot",),
    )


def test_to_json_is_the_rest_values_object(full_demo_a2l: A2lFile, hex_image: bytes) -> None:
    vals = read_values(full_demo_a2l, full_demo_a2l.get(MAP), hex_image)
    body = vals.to_json()
    assert body["axes"] == [[-100.0, 0.0, 100.0], [0.0, 1.0, 2.0, 3.0, 4.0]]
    assert np.array(body["values"]).shape == (3, 5)
    assert body["unit"] == "hours"
    assert body["axis_units"] == ["hours", ""]


def test_a_learned_map_is_quantised_and_round_trips_through_every_writer(
    full_demo_a2l: A2lFile, hex_image: bytes
) -> None:
    char = full_demo_a2l.get(MAP)
    current = read_values(full_demo_a2l, char, hex_image)
    learned = current.values * 0.5 + 0.3
    learned[2, 4] = 50000.0  # above the upper limit 32267
    vals, report = learned_values(char, current.axes, learned)
    assert report.clamped.sum() == 1
    assert vals.values[2, 4] == 32267.0
    assert np.all(vals.values == np.round(vals.values))  # SWORD, IDENTICAL
    np.testing.assert_allclose(report.error, vals.values - np.minimum(learned, 32267.0))

    patched = patch_image(full_demo_a2l, char, vals, hex_image)
    np.testing.assert_array_equal(decode_image(full_demo_a2l, char, patched).values, vals.values)
    np.testing.assert_array_equal(read_cdfx(write_cdfx([(char, vals)]))[MAP].values, vals.values)
    dcm_back = read_values(full_demo_a2l, char, write_dcm([(char, vals)]).encode())
    np.testing.assert_array_equal(dcm_back.values, vals.values)


def test_a_learned_map_with_the_wrong_axes_is_refused(full_demo_a2l: A2lFile) -> None:
    with pytest.raises(InputError, match=r"STD_AXIS\.STD_AXIS: the map has 1 axes"):
        learned_values(full_demo_a2l.get(MAP), [np.arange(3.0)], np.zeros(3))


def test_an_axis_whose_count_the_layout_fixes_must_match_exactly(full_demo_a2l: A2lFile) -> None:
    name = "ASAM.C.CURVE.RES_AXIS"  # FNC_VALUES only: all 9 points are stored
    data = _dcm_curve(name, list(range(8)), [0.0] * 8)
    with pytest.raises(InputError, match=r"RES_AXIS: axis X .* 8 points, the A2L RES_AXIS has 9"):
        read_values(full_demo_a2l, full_demo_a2l.get(name), data)


def test_dcm_values_of_a_scalar_are_refused_by_type(full_demo_a2l: A2lFile) -> None:
    data = _dcm_curve("OTHER.CURVE", [0, 1], [0, 0])
    name = "ASAM.C.SCALAR.UBYTE.IDENTICAL"
    with pytest.raises(InputError, match=r"UBYTE\.IDENTICAL: DCM values .* not for a VALUE"):
        read_values(full_demo_a2l, full_demo_a2l.get(name), data)


def test_dcm_block_kinds_follow_the_axis_types(full_demo_a2l: A2lFile, hex_image: bytes) -> None:
    names = [MAP, "ASAM.C.MAP.COM_AXIS.FIX_AXIS", "ASAM.C.CURVE.COM_AXIS", FIX_CURVE]
    chars = [full_demo_a2l.get(n) for n in names]
    items = [(c, read_values(full_demo_a2l, c, hex_image)) for c in chars]
    heads = [line for line in write_dcm(items).splitlines() if "KENN" in line]
    assert heads == [
        f"KENNFELD {MAP} 3 5",
        "GRUPPENKENNFELD ASAM.C.MAP.COM_AXIS.FIX_AXIS 8 3",
        "GRUPPENKENNLINIE ASAM.C.CURVE.COM_AXIS 8",
        f"FESTKENNLINIE {FIX_CURVE} 6",
    ]


def test_values_beyond_the_limits_are_refused_naming_cell_value_and_limit(
    full_demo_a2l: A2lFile, hex_image: bytes
) -> None:
    """Every format: a value outside [LowerLimit, UpperLimit] (-32268, 32267 for the demo's
    SWORD maps), a NaN, or a STD_AXIS point outside its axis' limits (-128, 127) is an
    InputError on ``values``; a value on the limit is read."""
    char = full_demo_a2l.get(MAP)
    current = read_values(full_demo_a2l, char, hex_image)
    on_limit = current.values.copy()
    on_limit[0, 0], on_limit[2, 4] = -32268.0, 32267.0
    vals = CalibrationValues(MAP, current.axes, on_limit)
    got = read_values(full_demo_a2l, char, write_cdfx([(char, vals)]))
    np.testing.assert_array_equal(got.values, on_limit)

    cases = [
        (1, 2, 32268.0, r"cell \(1, 2\) is 32268\.0, above the upper limit of \[-32268, 32267\]"),
        (0, 4, -1e6, r"cell \(0, 4\) is -1000000\.0, below the lower limit of"),
    ]
    for i, j, value, message in cases:
        bad = current.values.copy()
        bad[i, j] = value
        vals = CalibrationValues(MAP, current.axes, bad)
        for fmt, data in (
            ("DCM", write_dcm([(char, vals)]).encode()),
            ("CDFX", write_cdfx([(char, vals)])),
        ):
            with pytest.raises(InputError, match=rf"^{fmt} {re.escape(MAP)}: {message}") as e:
                read_values(full_demo_a2l, char, data)
            assert e.value.field == "values"

    nan = current.values.copy()
    nan[2, 0] = np.nan  # DCM and CDFX refuse a NaN themselves; a float image can hold one
    with pytest.raises(InputError, match=r"^HEX .*: cell \(2, 0\) is nan, not a number"):
        check_limits(char, CalibrationValues(MAP, current.axes, nan), source="HEX")

    axes = (np.array([-100.0, 0.0, 130.0]), current.axes[1])
    vals = CalibrationValues(MAP, axes, current.values)
    with pytest.raises(InputError, match=r"axis X \(.*\) point 2 is 130\.0, above the upper"):
        read_values(full_demo_a2l, char, write_dcm([(char, vals)]).encode())


def test_an_image_value_beyond_the_limits_is_refused(full_demo_a2l: A2lFile) -> None:
    """An SWORD can hold 32500, the demo's limit is 32267: decoded, then refused."""
    import struct

    _, records = known_values()
    name = "ASAM.C.CURVE.FIX_AXIS.PAR_DIST"  # FNC_VALUES only: six SWORDs at its address
    address = CURVES_FNC[name][0]
    records[address] = struct.pack("<6h", 1, 2, 3, 32500, 5, 6)
    char = full_demo_a2l.get(name)
    with pytest.raises(InputError, match=rf"^HEX {re.escape(name)}: cell \(3,\) is 32500\.0"):
        read_values(full_demo_a2l, char, image(records, "hex"))
