"""Quantising a learned map to what the ECU can hold: limits, data type and conversion."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from app.calibration.a2l import A2lFile
from app.calibration.model import CompuMethod
from app.calibration.quantize import quantize
from app.io.errors import InputError


def test_identical_sword_rounds_to_integers_and_reports_the_error(full_demo_a2l: A2lFile) -> None:
    char = full_demo_a2l.get("ASAM.C.MAP.STD_AXIS.STD_AXIS")  # SWORD, CM.IDENTICAL
    q = quantize(char, np.array([[1.2, -3.7], [10.5, 0.0]]))
    np.testing.assert_array_equal(q.values, [[1.0, -4.0], [10.0, 0.0]])  # half to even
    np.testing.assert_allclose(q.error, [[-0.2, -0.3], [-0.5, 0.0]], atol=1e-12)
    np.testing.assert_array_equal(q.raw, q.values)
    assert not q.clamped.any()
    assert q.max_abs_error == pytest.approx(0.5)


def test_values_outside_the_limits_are_clamped_and_marked(full_demo_a2l: A2lFile) -> None:
    char = full_demo_a2l.get("ASAM.C.CURVE.STD_AXIS")  # limits -32268 … 32267
    q = quantize(char, np.array([-40000.0, 0.0, 40000.0]))
    np.testing.assert_array_equal(q.values, [-32268.0, 0.0, 32267.0])
    np.testing.assert_array_equal(q.clamped, [True, False, True])
    np.testing.assert_array_equal(q.error, [0.0, 0.0, 0.0])  # error is after clamping


def test_strict_mode_names_the_characteristic_and_the_first_cell(full_demo_a2l: A2lFile) -> None:
    char = full_demo_a2l.get("ASAM.C.MAP.STD_AXIS.STD_AXIS")
    values = np.zeros((3, 5))
    values[1, 2] = 99999.0
    with pytest.raises(InputError, match=r"STD_AXIS: 1 value\(s\) outside the limits") as error:
        quantize(char, values, strict=True)
    assert "cell (1, 2)" in str(error.value)


def test_non_finite_values_are_refused(full_demo_a2l: A2lFile) -> None:
    char = full_demo_a2l.get("ASAM.C.CURVE.STD_AXIS")
    with pytest.raises(InputError, match=r"cell \(1,\) is not finite"):
        quantize(char, np.array([0.0, np.nan]))


def test_a_rational_conversion_rounds_on_its_raw_grid(full_demo_a2l: A2lFile) -> None:
    char = full_demo_a2l.get("ASAM.C.SCALAR.SWORD.RAT_FUNC_DIV_81_9175")  # raw = 81.9175·p
    q = quantize(char, np.array(20.0))
    assert q.raw == 1638.0  # round(1638.35)
    assert float(q.values) == pytest.approx(1638.0 / 81.9175)
    assert float(q.error) == pytest.approx(1638.0 / 81.9175 - 20.0)
    assert abs(float(q.error)) <= 0.5 / 81.9175


def test_rounding_never_steps_outside_a_limit_that_is_off_the_grid(
    full_demo_a2l: A2lFile,
) -> None:
    base = full_demo_a2l.get("ASAM.C.SCALAR.SWORD.LINEAR_MUL_2")
    # phys = 2·raw + 0: upper limit 9.0 lies between raw 4 (8.0) and raw 5 (10.0).
    char = dataclasses.replace(base, lower=-9.0, upper=9.0)
    q = quantize(char, np.array([9.0, -9.0, 8.9]))
    np.testing.assert_array_equal(q.values, [8.0, -8.0, 8.0])
    assert np.all(q.values <= 9.0)


def test_float_types_keep_float32_precision(full_demo_a2l: A2lFile) -> None:
    char = full_demo_a2l.get("ASAM.C.SCALAR.FLOAT32_IEEE.IDENTICAL")  # limits 10 … 200
    q = quantize(char, np.array(100.1))
    assert float(q.values) == float(np.float32(100.1))
    assert float(q.error) == pytest.approx(float(np.float32(100.1)) - 100.1)


def test_table_conversion_stores_a_table_entry(full_demo_a2l: A2lFile) -> None:
    base = full_demo_a2l.get("ASAM.C.SCALAR.SWORD.TAB_NOINTP_NO_DEFAULT_VALUE")
    cm = CompuMethod(name="T", kind="TAB_NOINTP", table=((0, 0.0), (1, 5.0), (2, 20.0)))
    char = dataclasses.replace(base, compu_method=cm, lower=0.0, upper=20.0)
    q = quantize(char, np.array([4.0, 13.0]))
    np.testing.assert_array_equal(q.raw, [1.0, 2.0])
    np.testing.assert_array_equal(q.values, [5.0, 20.0])
