"""Unit spellings that name the same unit (the run planner's column/role unit check)."""

from __future__ import annotations

import pytest

from app.io.columns import same_unit


@pytest.mark.parametrize(
    ("a", "b"),
    [("RPM", "1/min"), (" mg / stroke", "mg / stroke"), ("Nm", "N·m"), ("N m", "n·m")],
)
def test_same_unit(a: str, b: str) -> None:
    assert same_unit(a, b)


@pytest.mark.parametrize(("a", "b"), [("kPa", "Pa"), ("g/s", "kg/s"), ("rpm", "rad/s")])
def test_different_units(a: str, b: str) -> None:
    assert not same_unit(a, b)
