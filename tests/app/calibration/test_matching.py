"""Matching A2L input quantities to recorded channel names with tool suffixes."""

from __future__ import annotations

import pytest

from app.calibration.a2l import A2lFile
from app.calibration.matching import match_channels, strip_tool_suffix


@pytest.mark.parametrize(
    ("name", "base"),
    [
        ("nmot_w\\ETK:1", "nmot_w"),
        ("nmot_w\\CCP:1", "nmot_w"),
        ("nmot_w\\XCP:1", "nmot_w"),
        ("nmot_w\\ETK", "nmot_w"),
        ("nmot_w:1", "nmot_w"),
        ("nmot_w:12", "nmot_w"),
        ("ASAM.M.SCALAR.SBYTE.IDENTICAL\\XCP:1", "ASAM.M.SCALAR.SBYTE.IDENTICAL"),
        ("arr[3]", "arr[3]"),
        ("nmot_w", "nmot_w"),
        ("rl:w", "rl:w"),  # not an instance number
    ],
)
def test_strip_tool_suffix(name: str, base: str) -> None:
    assert strip_tool_suffix(name) == base


def test_exact_name_beats_a_suffixed_one() -> None:
    match = match_channels(["nmot_w"], ["nmot_w\\ETK:1", "nmot_w"])
    assert match.matched == {"nmot_w": "nmot_w"}
    assert match.ambiguous == {}


def test_suffixed_channel_matches_then_case_insensitive() -> None:
    match = match_channels(
        ["nmot_w", "rl_w", "TMOT"], ["time", "nmot_w\\ETK:1", "RL_W:1", "tmot\\XCP:1"]
    )

    assert match.matched == {"nmot_w": "nmot_w\\ETK:1", "rl_w": "RL_W:1", "TMOT": "tmot\\XCP:1"}
    assert match.unmatched == []
    assert match.message() == ""


def test_case_sensitive_match_wins_over_case_insensitive() -> None:
    match = match_channels(["Rl_w"], ["rl_w\\ETK:1", "Rl_w\\CCP:1"])
    assert match.matched == {"Rl_w": "Rl_w\\CCP:1"}


def test_two_devices_recording_the_same_quantity_are_reported() -> None:
    match = match_channels(["nmot_w"], ["nmot_w\\ETK:1", "nmot_w\\XCP:1"])
    assert match.matched == {"nmot_w": "nmot_w\\ETK:1"}
    assert match.ambiguous == {"nmot_w": ["nmot_w\\XCP:1"]}


def test_unmatched_quantities_are_listed_with_similar_channels() -> None:
    match = match_channels(["nmot_w", "wped", "rl_w"], ["nmot\\ETK:1", "rl_w:1", "speed"])

    assert match.matched == {"rl_w": "rl_w:1"}
    assert match.unmatched == ["nmot_w", "wped"]
    assert match.suggestions["nmot_w"] == ["nmot\\ETK:1"]
    assert match.message().startswith("no channel for 'nmot_w' (similar: nmot\\ETK:1); 'wped'")


def test_demo_map_axes_against_recorded_names(demo_a2l: A2lFile) -> None:
    quantities = [axis.input_quantity for axis in demo_a2l.get("ASAM.C.MAP.STD_AXIS.STD_AXIS").axes]
    channels = ["ASAM.M.SCALAR.SBYTE.IDENTICAL\\XCP:1", "time"]

    match = match_channels(quantities, channels)
    assert match.matched == {
        "ASAM.M.SCALAR.SBYTE.IDENTICAL": "ASAM.M.SCALAR.SBYTE.IDENTICAL\\XCP:1"
    }
    assert match.unmatched == ["ASAM.M.SCALAR.UBYTE.TAB_VERB_NO_DEFAULT_VALUE"]
