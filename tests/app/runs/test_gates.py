"""Sample gates against a slow per-sample reference, and their validation errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.io.errors import InputError
from app.runs.gates import (
    HoldoffGate,
    RangeGate,
    RateGate,
    apply_gates,
    gate_labels,
    nearest_cell,
    parse_gates,
    rejected_per_cell,
    scan_gates,
)
from estimation import Signals
from estimation.table import Axis, Grid


def drive(n: int = 3000, seed: int = 0) -> Signals:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.005, 0.02, n))  # irregular sampling
    throttle = np.cumsum(rng.normal(0, 2.0, n))
    coolant = 60 + np.cumsum(rng.normal(0.01, 0.2, n))
    fuel = np.where(rng.random(n) < 0.01, 0.0, rng.uniform(1, 30, n))
    speed = rng.uniform(600, 4500, n)
    return Signals(
        t,
        {"throttle": throttle, "coolant": coolant, "fuel": fuel, "speed": speed},
        {"throttle": "%", "coolant": "degC", "fuel": "mg/stroke", "speed": "rpm"},
    )


def reference_mask(gate, signals: Signals) -> np.ndarray:
    """One sample at a time, straight from the definitions in the module docstring."""
    t, x = signals.time, signals[gate.channel]
    n = len(t)
    out = np.zeros(n, dtype=bool)
    for k in range(n):
        if isinstance(gate, RangeGate):
            lo = -math.inf if gate.min is None else gate.min
            hi = math.inf if gate.max is None else gate.max
            out[k] = x[k] < lo or x[k] > hi
        elif isinstance(gate, RateGate):
            j = max(k, 1)
            out[k] = abs((x[j] - x[j - 1]) / (t[j] - t[j - 1])) > gate.max_abs
        else:
            for i in range(k, -1, -1):
                if t[k] - t[i] > gate.seconds:
                    break
                event = x[i] < gate.below if gate.below is not None else x[i] > gate.above
                if event:
                    out[k] = True
                    break
    return out


GATES = [
    {"type": "range", "channel": "coolant", "min": 70},
    {"type": "range", "channel": "coolant", "max": 65.5},
    {"type": "range", "channel": "speed", "min": 1000, "max": 4000},
    {"type": "rate", "channel": "throttle", "max_abs": 150.0},
    {"type": "holdoff", "channel": "fuel", "below": 0.5, "seconds": 0.5},
    {"type": "holdoff", "channel": "speed", "above": 4400, "seconds": 0.0},
    {"type": "holdoff", "channel": "throttle", "above": 10, "seconds": 2.0},
]


@pytest.mark.parametrize("raw", GATES, ids=[f"{g['type']}-{g['channel']}" for g in GATES])
def test_each_gate_matches_the_per_sample_reference(raw: dict) -> None:
    signals = drive()
    (gate,) = parse_gates([raw], signals.names)
    result = apply_gates([gate], signals)
    expected = reference_mask(gate, signals)
    assert 0 < expected.sum() < len(signals)  # the case exercises both outcomes
    (mask,) = result.masks.values()
    np.testing.assert_array_equal(mask, expected)
    np.testing.assert_array_equal(result.accept, ~expected)


@pytest.mark.parametrize("window", [2, 3, 97, 1000, 5000])
def test_a_scan_a_window_at_a_time_gives_the_whole_log_gates(window: int) -> None:
    """A streamed run's gates (rate and holdoff carry across a window's edge) equal the
    whole log's, bit for bit, and the scan reads each row once, ``window`` at a time."""
    signals = drive()
    gates = parse_gates(GATES, signals.names)
    whole = apply_gates(gates, signals)
    reads: list[tuple[int, int]] = []

    def read(a: int, z: int) -> Signals:
        reads.append((a, z))
        return signals.slice(a, z)

    scanned = scan_gates(gates, read, len(signals), window=window)
    assert scanned.masks.keys() == whole.masks.keys()
    for label, mask in whole.masks.items():
        np.testing.assert_array_equal(scanned.masks[label], mask)
    np.testing.assert_array_equal(scanned.accept, whole.accept)
    assert (scanned.rejected, scanned.failed) == (whole.rejected, whole.failed)
    assert [z - a for a, z in reads] == [
        min(window, len(signals) - a) for a in range(0, len(signals), window)
    ]


def test_holdoff_covers_exactly_the_seconds_after_the_event() -> None:
    t = np.arange(10) * 0.5
    fuel = np.array([5, 5, 0, 0, 5, 5, 5, 5, 0, 5], dtype=float)
    signals = Signals(t, {"fuel": fuel})
    gate = HoldoffGate(channel="fuel", below=0.1, seconds=1.0)
    mask = apply_gates([gate], signals).masks["holdoff:fuel"]
    # event at t=1.0, 1.5 → rejected through t=2.5; event at 4.0 → through 4.5 (end)
    np.testing.assert_array_equal(mask, [0, 0, 1, 1, 1, 1, 0, 0, 1, 1])


def test_counts_attribute_each_sample_to_its_first_gate() -> None:
    signals = drive()
    gates = parse_gates(GATES, signals.names)
    result = apply_gates(gates, signals)
    masks = [reference_mask(g, signals) for g in gates]
    labels = gate_labels(gates)
    assert labels[:2] == ["range:coolant", "range:coolant#2"]
    np.testing.assert_array_equal(result.accept, ~np.logical_or.reduce(masks))
    taken = np.zeros(len(signals), dtype=bool)
    for label, mask in zip(labels, masks, strict=True):
        assert result.failed[label] == mask.sum()
        assert result.rejected[label] == (mask & ~taken).sum()
        taken |= mask
    assert sum(result.rejected.values()) == (~result.accept).sum()


def test_rejections_per_cell() -> None:
    signals = drive()
    gates = parse_gates(GATES[:4], signals.names)
    result = apply_gates(gates, signals)
    grid = Grid([Axis("speed", "rpm", [500, 1500, 2500, 3500, 4500]), Axis("fuel", "mg", [0, 30])])
    idx, w = grid.regressor(signals.stack(["speed", "fuel"]))
    cell = nearest_cell(idx, w)
    per_cell = rejected_per_cell(result, cell, None, grid.size)
    weighted = rejected_per_cell(result, idx, w, grid.size)
    for label, mask in result.first_gate().items():
        slow = np.zeros(grid.size, dtype=np.int64)
        slow_w = np.zeros(grid.size)
        for k in np.flatnonzero(mask):
            slow[idx[k, np.argmax(w[k])]] += 1
            for c in range(idx.shape[1]):
                slow_w[idx[k, c]] += w[k, c]
        np.testing.assert_array_equal(per_cell[label], slow)
        np.testing.assert_allclose(weighted[label], slow_w, rtol=1e-12)
        assert per_cell[label].sum() == result.rejected[label]
    independent = rejected_per_cell(result, cell, None, grid.size, attributed=False)
    assert {k: int(v.sum()) for k, v in independent.items()} == result.failed


BAD = [
    ([{"type": "range", "channel": "oil"}], "config.gates[0]", "needs 'min', 'max' or both"),
    (
        [{"type": "range", "channel": "nope", "min": 1}],
        "config.gates[0].channel",
        "unknown channel 'nope'",
    ),
    (
        [{"type": "range", "channel": "oil", "min": 5, "max": 1}],
        "config.gates[0]",
        "min 5 is above max 1",
    ),
    ([{"type": "range", "channel": "oil", "min": "x"}], "config.gates[0].min", "valid number"),
    ([{"type": "range", "channel": "oil", "min": float("nan")}], "config.gates[0].min", "finite"),
    (
        [{"type": "rate", "channel": "oil", "max_abs": 0}],
        "config.gates[0].max_abs",
        "greater than 0",
    ),
    ([{"type": "rate", "channel": "oil"}], "config.gates[0].max_abs", "Field required"),
    (
        [{"type": "holdoff", "channel": "oil", "seconds": 1}],
        "config.gates[0]",
        "exactly one of 'below' or 'above'",
    ),
    (
        [{"type": "holdoff", "channel": "oil", "below": 1, "above": 2, "seconds": 1}],
        "config.gates[0]",
        "exactly one",
    ),
    (
        [{"type": "holdoff", "channel": "oil", "below": 1, "seconds": -1}],
        "config.gates[0].seconds",
        "greater than or equal to 0",
    ),
    (
        [{"type": "range", "channel": "oil", "min": 1}, {"type": "blend", "channel": "oil"}],
        "config.gates[1]",
        "'blend'",
    ),
    (
        [{"type": "range", "channel": "oil", "min": 1, "mx": 3}],
        "config.gates[0].mx",
        "Extra inputs",
    ),
    ({"type": "range"}, "config.gates", "valid list"),
]


@pytest.mark.parametrize(("raw", "field", "message"), BAD)
def test_bad_gates_name_the_field(raw: object, field: str, message: str) -> None:
    with pytest.raises(InputError) as info:
        parse_gates(raw, ["oil"])
    assert (info.value.field, info.value.code, info.value.status) == (
        field,
        "validation_error",
        422,
    )
    assert message in info.value.message


def test_no_gates_accept_everything() -> None:
    signals = drive(10)
    assert parse_gates(None, signals.names) == []
    result = apply_gates([], signals)
    assert result.accept.all()
    assert result.rejected == {}
