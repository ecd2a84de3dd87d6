"""CDFX (ASAM CDF 2.0) written and read back: structure, DCM → CDFX → DCM, safety."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from app.calibration.a2l import A2lFile
from app.calibration.cdfx import read_cdfx, write_cdfx
from app.calibration.image import decode_image
from app.calibration.values import CalibrationValues, read_values, write_dcm
from app.io.errors import InputError
from tests.app.calibration.encode import image, known_values


@pytest.fixture(scope="module")
def demo_items(full_demo_a2l: A2lFile) -> list:
    """Every MAP and CURVE of the demo with full-precision (non-integer) values."""
    known, records = known_values()
    data = image(records, "hex")
    rng = np.random.default_rng(7)
    items = []
    for name in known:
        char = full_demo_a2l.get(name)
        vals = decode_image(full_demo_a2l, char, data)
        vals.values = vals.values / 3.0 + rng.normal(size=vals.values.shape) * 1e-7
        items.append((char, vals))
    return items


def test_cdfx_has_the_asam_cdf20_structure(full_demo_a2l: A2lFile, demo_items: list) -> None:
    root = ET.fromstring(write_cdfx(demo_items))
    assert root.tag == "MSRSW"
    assert root.findtext("CATEGORY") == "CDF20"
    tree = root.find("SW-SYSTEMS/SW-SYSTEM/SW-INSTANCE-SPEC/SW-INSTANCE-TREE")
    assert tree is not None
    instances = {i.findtext("SHORT-NAME"): i for i in tree.findall("SW-INSTANCE")}
    for char, vals in demo_items:
        instance = instances[char.name]
        assert instance.findtext("CATEGORY") == char.type
        assert instance.findtext("SW-VALUE-CONT/UNIT-DISPLAY-NAME") == char.unit
        axes = instance.findall("SW-AXIS-CONTS/SW-AXIS-CONT")
        assert [a.findtext("CATEGORY") for a in axes] == [a.attribute for a in char.axes]
        for axis, points in zip(axes, vals.axes, strict=True):
            assert [float(v.text) for v in axis.findall("SW-VALUES-PHYS/V")] == list(points)
    the_map = instances["ASAM.C.MAP.STD_AXIS.STD_AXIS"]
    groups = the_map.findall("SW-VALUE-CONT/SW-VALUES-PHYS/VG")
    assert [len(g.findall("V")) for g in groups] == [5, 5, 5]  # one VG per X point
    com = instances["ASAM.C.CURVE.COM_AXIS"].find("SW-AXIS-CONTS/SW-AXIS-CONT")
    assert com.findtext("SW-INSTANCE-REF") == "ASAM.C.AXIS_PTS.UBYTE_8"
    assert instances["ASAM.C.AXIS_PTS.UBYTE_8"].findtext("CATEGORY") == "COM_AXIS"


def test_cdfx_reads_back_bit_exactly(demo_items: list) -> None:
    found = read_cdfx(write_cdfx(demo_items))
    for char, vals in demo_items:
        got = found[char.name]
        assert got.values.tobytes() == np.asarray(vals.values, dtype=np.float64).tobytes()
        for a, b in zip(got.axes, vals.axes, strict=True):
            assert a.tobytes() == np.asarray(b, dtype=np.float64).tobytes()
        assert got.unit == vals.unit
        assert got.axis_units == vals.axis_units


def test_dcm_to_cdfx_to_dcm_is_lossless(full_demo_a2l: A2lFile, demo_items: list) -> None:
    dcm = write_dcm(demo_items).encode("utf-8")
    from_dcm = [(c, read_values(full_demo_a2l, c, dcm)) for c, _ in demo_items]
    cdfx = write_cdfx(from_dcm)
    from_cdfx = [(c, read_values(full_demo_a2l, c, cdfx)) for c, _ in demo_items]
    assert write_dcm(from_cdfx) == dcm.decode("utf-8")
    for (_, a), (_, b) in zip(from_dcm, from_cdfx, strict=True):
        assert a.values.tobytes() == b.values.tobytes()


def test_values_without_a_characteristic_are_written_by_their_shape() -> None:
    curve = CalibrationValues("k", (np.array([0.0, 1.0]),), np.array([0.1, 0.2]), "Nm", ("rpm",))
    scalar = CalibrationValues("s", (), np.array(1.5), "bar")
    block = CalibrationValues("b", (), np.arange(6.0).reshape(2, 3), "")
    root = ET.fromstring(write_cdfx([(None, curve), (None, scalar), (None, block)]))
    categories = [i.findtext("CATEGORY") for i in root.iter("SW-INSTANCE")]
    assert categories == ["CURVE", "VALUE", "VAL_BLK"]
    back = read_cdfx(write_cdfx([(None, curve), (None, scalar), (None, block)]))
    assert back["s"].values.shape == ()
    np.testing.assert_array_equal(back["b"].values, block.values)


INCA_LIKE = b"""<?xml version="1.0" encoding="ISO-8859-1"?>
<!DOCTYPE MSRSW PUBLIC "-//ASAM//DTD CALIBRATION DATA FORMAT:V2.0.0:LAI:IAI:XML:CDF200.XSD//EN"
  "cdf_v2.0.0.sl.dtd">
<MSRSW>
  <SHORT-NAME>CalDemo</SHORT-NAME>
  <CATEGORY>CDF20</CATEGORY>
  <SW-SYSTEMS><SW-SYSTEM><SHORT-NAME>x</SHORT-NAME>
    <SW-INSTANCE-SPEC><SW-INSTANCE-TREE><SHORT-NAME>t</SHORT-NAME><CATEGORY>VCD</CATEGORY>
      <SW-INSTANCE>
        <SHORT-NAME>AXIS.SHARED</SHORT-NAME><CATEGORY>COM_AXIS</CATEGORY>
        <SW-VALUE-CONT><UNIT-DISPLAY-NAME>rpm</UNIT-DISPLAY-NAME>
          <SW-VALUES-PHYS><V>1000</V><V>2000</V></SW-VALUES-PHYS></SW-VALUE-CONT>
      </SW-INSTANCE>
      <SW-INSTANCE>
        <SHORT-NAME>KL.SHARED</SHORT-NAME><CATEGORY>CURVE</CATEGORY>
        <SW-VALUE-CONT><UNIT-DISPLAY-NAME>Nm</UNIT-DISPLAY-NAME>
          <SW-VALUES-PHYS><V>1.5</V><V>2.5</V></SW-VALUES-PHYS></SW-VALUE-CONT>
        <SW-AXIS-CONTS><SW-AXIS-CONT><CATEGORY>COM_AXIS</CATEGORY>
          <SW-INSTANCE-REF>AXIS.SHARED</SW-INSTANCE-REF></SW-AXIS-CONT></SW-AXIS-CONTS>
      </SW-INSTANCE>
      <SW-INSTANCE><SHORT-NAME>TEXT</SHORT-NAME><CATEGORY>ASCII</CATEGORY></SW-INSTANCE>
    </SW-INSTANCE-TREE></SW-INSTANCE-SPEC></SW-SYSTEM></SW-SYSTEMS>
</MSRSW>
"""


def test_an_external_doctype_and_instance_references_are_read() -> None:
    found = read_cdfx(INCA_LIKE)
    assert set(found) == {"AXIS.SHARED", "KL.SHARED"}
    np.testing.assert_array_equal(found["KL.SHARED"].axes[0], [1000.0, 2000.0])
    np.testing.assert_array_equal(found["KL.SHARED"].values, [1.5, 2.5])


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            b'<?xml version="1.0"?><!DOCTYPE MSRSW [<!ENTITY a "aaaa">]><MSRSW>&a;</MSRSW>',
            "entities",
        ),
        (b"<!DOCTYPE MSRSW [<!ELEMENT MSRSW ANY>]><MSRSW/>", "internal DTD subset"),
        (b"<MSRSW><SW-INSTANCE>", "not well-formed"),
        (b"<OTHER/>", "not <MSRSW>"),
        (b"<MSRSW><SHORT-NAME>x</SHORT-NAME></MSRSW>", "no SW-INSTANCE"),
        (
            INCA_LIKE.replace(b"<V>1.5</V>", b"<VT>on</VT>"),
            r"KL\.SHARED: verbal values \(VT\)",
        ),
        (INCA_LIKE.replace(b"<V>1.5</V>", b"<V>NaN</V>"), "must be finite"),
        (INCA_LIKE.replace(b"<V>1.5</V>", b"<V>1,5</V>"), "non-numeric value '1,5'"),
        (
            INCA_LIKE.replace(b"<SW-INSTANCE-REF>AXIS.SHARED", b"<SW-INSTANCE-REF>NOPE"),
            "refers to 'NOPE'",
        ),
    ],
    ids=["entity", "internal-dtd", "malformed", "root", "empty", "verbal", "nan", "comma", "ref"],
)
def test_bad_cdfx_is_refused_with_a_reason(data: bytes, message: str) -> None:
    with pytest.raises(InputError, match=message) as error:
        read_cdfx(data)
    assert error.value.field == "values"


def test_a_too_large_cdfx_is_refused() -> None:
    with pytest.raises(InputError, match="at most 100 are read") as error:
        read_cdfx(INCA_LIKE, max_bytes=100)
    assert error.value.status == 413
