"""Column mapping: dataset channels → an estimator's signal roles, problems named."""

from __future__ import annotations

import pytest

from app.io.columns import SignalRole, map_columns, require_columns, same_unit
from app.io.errors import InputError
from estimation import Signals

CHANNELS = [
    {"name": "engine_speed", "unit": "1/min"},
    {"name": "nox", "unit": "ppm"},
    {"name": "p_im", "unit": "Pa"},
    {"name": "y", "unit": "kPa"},
]
ROLES = [
    SignalRole("y", "ppm", "measured table output"),
    SignalRole("speed", "rpm"),
    SignalRole("p_im", "Pa"),
    SignalRole("trigger", required=False),
]


def test_mapping_with_defaults_units_and_optional_roles() -> None:
    mapping = map_columns(CHANNELS, ROLES, {"y": "nox", "speed": "engine_speed"})
    assert mapping.columns == {"y": "nox", "speed": "engine_speed", "p_im": "p_im"}
    assert mapping.units == {"y": "ppm", "speed": "1/min", "p_im": "Pa"}
    assert mapping.unit_mismatches == {}  # 1/min is rpm


def test_unit_mismatch_is_reported_or_refused() -> None:
    mapping = map_columns(CHANNELS, ROLES, {"speed": "engine_speed"})  # y defaults to 'y' [kPa]
    assert mapping.unit_mismatches == {"y": ("ppm", "kPa")}
    with pytest.raises(InputError, match="'y' is in 'kPa', expected 'ppm'") as info:
        map_columns(CHANNELS, ROLES, {"speed": "engine_speed"}, check_units=True)
    assert info.value.field == "signals.y"


@pytest.mark.parametrize(
    ("mapping", "field", "message"),
    [
        (
            {"y": "nox", "speed": "engine_speed", "lambda": "x"},
            "signals.lambda",
            "unknown signal role 'lambda'",
        ),
        ({"y": "nox", "speed": "rpm"}, "signals.speed", "column 'rpm' is not in the dataset"),
        ({"y": "nox"}, "signals.speed", "signal 'speed' is required"),
    ],
)
def test_problems_are_named(mapping: dict, field: str, message: str) -> None:
    with pytest.raises(InputError) as info:
        map_columns(CHANNELS, ROLES, mapping)
    assert (info.value.field, info.value.code) == (field, "validation_error")
    assert message in info.value.message
    assert "engine_speed" in info.value.message or "unknown" in message


def test_no_default_to_role_name_and_signals_input() -> None:
    signals = Signals([0.0, 1.0], {"p_im": [1.0, 2.0]}, {"p_im": "Pa"})
    with pytest.raises(InputError, match="'p_im' is required"):
        map_columns(signals, ROLES[2:], {}, default_to_role_name=False)
    assert map_columns(signals, ROLES[2:], {}).columns == {"p_im": "p_im"}


def test_require_columns_names_the_axis() -> None:
    require_columns(CHANNELS, ["engine_speed", "p_im"], field="table.axes")
    with pytest.raises(InputError) as info:
        require_columns({"a": ""}, ["a", "b"], field="table.axes")
    assert info.value.field == "table.axes[1].name"


def test_same_unit() -> None:
    assert same_unit("RPM", "1/min")
    assert same_unit(" mg / stroke", "mg / stroke")
    assert not same_unit("kPa", "Pa")
