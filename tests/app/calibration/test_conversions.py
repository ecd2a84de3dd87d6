"""COMPU_METHOD conversions (ASAM MCD-2 MC) and ASAM data types."""

from __future__ import annotations

import numpy as np
import pytest

from app.calibration.a2l import A2lFile
from app.calibration.conversions import to_physical, to_raw, to_raw_exact
from app.calibration.datatypes import datatype
from app.calibration.model import CompuMethod
from app.io.errors import InputError


def rat(a: float, b: float, c: float, d: float, e: float, f: float) -> CompuMethod:
    return CompuMethod(name="CM.TEST", kind="RAT_FUNC", coeffs=(a, b, c, d, e, f))


@pytest.mark.parametrize(
    ("name", "dtype", "lo", "hi"),
    [
        ("UBYTE", "u1", 0, 255),
        ("SBYTE", "i1", -128, 127),
        ("UWORD", "u2", 0, 65535),
        ("SWORD", "i2", -32768, 32767),
        ("ULONG", "u4", 0, 2**32 - 1),
        ("SLONG", "i4", -(2**31), 2**31 - 1),
        ("A_UINT64", "u8", 0, 2**64 - 1),
        ("A_INT64", "i8", -(2**63), 2**63 - 1),
    ],
)
def test_integer_datatypes_have_their_numpy_type_and_range(
    name: str, dtype: str, lo: int, hi: int
) -> None:
    big, little = datatype(name, "MSB_FIRST"), datatype(name, "MSB_LAST")
    assert big.dtype == np.dtype(">" + dtype)
    assert little.dtype == np.dtype("<" + dtype)
    assert (big.min, big.max) == (float(lo), float(hi))
    assert big.is_integer


def test_byte_order_decides_how_bytes_read() -> None:
    assert datatype("UWORD", "MSB_FIRST").decode(b"\x12\x34", 1)[0] == 0x1234
    assert datatype("UWORD", "MSB_LAST").decode(b"\x12\x34", 1)[0] == 0x3412
    assert datatype("FLOAT32_IEEE", "MSB_LAST").encode(np.array([1.5])) == b"\x00\x00\xc0\x3f"
    assert datatype("FLOAT64_IEEE", "MSB_FIRST").decode(b"\x3f\xf8" + bytes(6), 1)[0] == 1.5


def test_unknown_datatype_and_byte_order_are_refused() -> None:
    with pytest.raises(InputError, match="data type 'BIT42' is not supported"):
        datatype("BIT42", "MSB_LAST", what="characteristic K")
    with pytest.raises(InputError, match="byte order 'MIDDLE' is not"):
        datatype("UBYTE", "MIDDLE")


def test_linear_is_a_times_raw_plus_b_and_inverts() -> None:
    cm = CompuMethod(name="CM.LIN", kind="LINEAR", coeffs=(0.25, -10.0))
    raw = np.array([0.0, 4.0, 100.0])
    np.testing.assert_allclose(to_physical(cm, raw), [-10.0, -9.0, 15.0])
    np.testing.assert_allclose(to_raw_exact(cm, to_physical(cm, raw)), raw)


def test_rat_func_coefficients_map_physical_to_internal() -> None:
    # ASAM: raw = (a·p² + b·p + c) / (d·p² + e·p + f); here raw = 10·p + 3 (b = 10, c = 3).
    cm = rat(0, 10, 3, 0, 0, 1)
    assert to_raw_exact(cm, np.array(2.5)) == pytest.approx(28.0)
    assert to_physical(cm, np.array(28.0)) == pytest.approx(2.5)


def test_rat_func_with_a_linear_denominator_inverts_in_closed_form() -> None:
    cm = rat(0, 2, 1, 0, 1, 4)  # raw = (2p + 1) / (p + 4)
    phys = np.array([-3.0, 0.0, 1.0, 10.0])
    np.testing.assert_allclose(to_physical(cm, to_raw_exact(cm, phys)), phys, rtol=1e-12)


def test_quadratic_rat_func_picks_the_root_that_maps_back() -> None:
    cm = rat(1, 0, 0, 0, 0, 1)  # raw = p²: the positive root is taken
    np.testing.assert_allclose(to_physical(cm, np.array([0.0, 4.0, 9.0])), [0.0, 2.0, 3.0])


def test_rat_func_without_a_physical_value_is_named() -> None:
    cm = rat(1, 0, 0, 0, 0, 1)  # raw = p² has no real p for raw < 0
    with pytest.raises(InputError, match=r"CM\.TEST: RAT_FUNC has no physical value for raw -4$"):
        to_physical(cm, np.array([-4.0]))


def test_tab_intp_interpolates_and_holds_at_the_ends() -> None:
    cm = CompuMethod(name="T", kind="TAB_INTP", table=((0, 0.0), (10, 100.0), (20, 150.0)))
    np.testing.assert_allclose(
        to_physical(cm, np.array([-5.0, 5.0, 15.0, 30.0])), [0.0, 50.0, 125.0, 150.0]
    )
    np.testing.assert_allclose(to_raw_exact(cm, np.array([50.0, 125.0])), [5.0, 15.0])


def test_tab_nointp_takes_the_nearest_entry() -> None:
    cm = CompuMethod(name="T", kind="TAB_NOINTP", table=((0, 1.0), (10, 2.0), (20, 4.0)))
    np.testing.assert_allclose(to_physical(cm, np.array([4.0, 5.0, 6.0, 19.0])), [1, 1, 2, 4])
    np.testing.assert_allclose(to_raw_exact(cm, np.array([1.9, 3.5])), [10.0, 20.0])


def test_tab_verb_keeps_the_numeric_raw_value() -> None:
    cm = CompuMethod(name="V", kind="TAB_VERB", verbal=((0, "off"), (1, "on")))
    np.testing.assert_array_equal(to_physical(cm, np.array([0.0, 1.0, 7.0])), [0, 1, 7])


def test_unsupported_kinds_and_bad_tables_are_refused() -> None:
    with pytest.raises(InputError, match="conversion type FORM is not supported"):
        to_physical(CompuMethod(name="F", kind="FORM", formula="X1+4"), np.array([1.0]))
    with pytest.raises(InputError, match=r"COMPU_METHOD CM\.X is referenced but not defined"):
        to_physical(CompuMethod(name="CM.X", kind="UNDEFINED"), np.array([1.0]))
    with pytest.raises(InputError, match="LINEAR needs 2 coefficients"):
        to_physical(CompuMethod(name="L", kind="LINEAR", coeffs=(1.0,)), np.array([1.0]))
    with pytest.raises(InputError, match="LINEAR with a = 0 cannot be inverted"):
        to_raw_exact(CompuMethod(name="L", kind="LINEAR", coeffs=(0.0, 1.0)), np.array([1.0]))
    with pytest.raises(InputError, match="empty conversion table"):
        to_physical(CompuMethod(name="T", kind="TAB_INTP"), np.array([1.0]))
    flat = CompuMethod(name="T", kind="TAB_INTP", table=((0, 1.0), (1, 1.0)))
    with pytest.raises(InputError, match="not strictly monotone"):
        to_raw_exact(flat, np.array([1.0]))


def test_to_raw_rounds_and_saturates_to_the_datatype() -> None:
    cm = CompuMethod(name="L", kind="LINEAR", coeffs=(0.5, 0.0))
    raw = to_raw(cm, np.array([10.2, 10.3, -1000.0, 1000.0]), datatype("SBYTE"))
    np.testing.assert_array_equal(raw, [20.0, 21.0, -128.0, 127.0])
    floats = to_raw(None, np.array([0.1, 1e40]), datatype("FLOAT32_IEEE"))
    assert floats[0] == float(np.float32(0.1))
    assert floats[1] == float(np.finfo(np.float32).max)


def test_the_demo_conversions(full_demo_a2l: A2lFile) -> None:
    """The demo's own COMPU_METHODs as pya2ldb reads them (the completed copy)."""
    get = full_demo_a2l.get
    div_10 = get("ASAM.C.SCALAR.SWORD.RAT_FUNC_DIV_10").compu_method
    assert div_10.kind == "RAT_FUNC"
    assert to_physical(div_10, np.array([123.0])) == pytest.approx(12.3)
    div_81 = get("ASAM.C.SCALAR.SWORD.RAT_FUNC_DIV_81_9175").compu_method
    assert to_raw(div_81, np.array([1.0]), datatype("SWORD"))[0] == 82.0
    mul_2 = get("ASAM.C.SCALAR.SWORD.LINEAR_MUL_2").compu_method
    assert to_physical(mul_2, np.array([-7.0]))[0] == -14.0
    tab = get("ASAM.C.SCALAR.SWORD.TAB_INTP_NO_DEFAULT_VALUE").compu_method
    assert tab.kind == "TAB_INTP"
    assert to_physical(tab, np.array([2.5]))[0] == pytest.approx(25.0)  # pairs i → 10·i
