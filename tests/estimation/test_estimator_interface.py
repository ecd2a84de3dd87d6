"""The estimator interface: registry, schemas, snapshots, and class vs procedure form."""

from __future__ import annotations

import json

import numpy as np
import pytest

from estimation import ConfigError, SignalError, Signals
from estimation.errors import StateError
from estimation.filters.functions import run_chunk
from estimation.filters.settings import grid_of, resolve_settings
from estimation.registry import get_spec, registry

FILTERS = ["kf", "skf", "sskf", "rls", "nlms"]


def drive(n: int = 600, seed: int = 3) -> Signals:
    rng = np.random.default_rng(seed)
    u1 = np.clip(2000 + np.cumsum(rng.normal(0, 40, n)), 300, 3700)
    u2 = np.clip(30 + np.cumsum(rng.normal(0, 1.5, n)), -5, 65)
    y = np.sin(u1 / 900.0) + 0.02 * u2 + rng.normal(0, 0.05, n)
    return Signals(np.arange(n) * 0.02, {"u1": u1, "u2": u2, "y": y}, {"u1": "rpm"})


def config(name: str, **extra: object) -> dict[str, object]:
    base: dict[str, object] = {
        "axes": [
            {"name": "u1", "breakpoints": [500, 1200, 2500, 3500], "unit": "rpm"},
            {"name": "u2", "breakpoints": [0, 25, 60]},
        ],
        "output": "y",
    }
    if name in ("kf", "skf"):
        base |= {"sigma_w": 0.02, "sigma_v": 0.05, "p0": 1.0}
    return base | extra


def test_registry_lists_every_filter_with_a_renderable_schema() -> None:
    specs = registry()
    assert set(FILTERS) <= set(specs)
    for name in FILTERS:
        entry = specs[name].catalog_entry()
        assert entry["name"] == name
        assert entry["paper"]
        schema = entry["config_schema"]
        json.dumps(schema)  # the dashboard receives it as JSON
        assert {"axes", "output"} <= set(schema["required"])
        assert "gate_sigma" in schema["properties"]


def test_unknown_estimator_and_unknown_config_key_are_named() -> None:
    with pytest.raises(ConfigError, match=r"unknown estimator 'kalman'.*'skf'"):
        get_spec("kalman")
    with pytest.raises(ConfigError, match=r"skf: sigma_x: Extra inputs are not permitted"):
        get_spec("skf").build(config("skf", sigma_x=1.0))
    with pytest.raises(ConfigError, match=r"axes.0.breakpoints: .*strictly increasing"):
        get_spec("kf").build(config("kf") | {"axes": [{"name": "u1", "breakpoints": [2, 1]}]})


@pytest.mark.parametrize("name", FILTERS)
def test_class_and_procedure_forms_agree(name: str) -> None:
    """FilterPy's procedure-form test: the estimator class equals the pure functions."""
    signals = drive()
    estimator = get_spec(name).build(config(name, gate_sigma=2.5))
    final = estimator.fit(signals)

    settings = resolve_settings(estimator.config, grid_of(estimator.config))
    prepared = estimator.prepare(signals)
    state = estimator.initial_state(prepared)
    for start in range(0, 600, 250):
        sl = slice(start, start + 250)
        state, _, _ = run_chunk(
            state, prepared.idx[sl], prepared.w[sl], prepared.y[sl], None, settings
        )
    assert np.array_equal(state.theta, final.state.theta)
    assert state.rejected_gate == final.rejected["innovation"]


def test_snapshots_cover_the_log_chunk_by_chunk_with_a_sensor_delay() -> None:
    signals = drive()
    sensor = {"lag": 0.8, "delay_samples": 7, "sigma_f": 0.05}
    estimator = get_spec("skf").build(config("skf", sensor=sensor))
    snaps = list(estimator.run(signals, every=100))
    assert [s.chunk_start for s in snaps] == [0, 107, 207, 307, 407, 507]
    assert snaps[-1].done
    assert not snaps[0].done
    assert [s.sample for s in snaps] == [107, 207, 307, 407, 507, 600]
    status = np.concatenate([s.status for s in snaps])
    prediction = np.concatenate([s.outputs["prediction"] for s in snaps])
    residual = np.concatenate([s.outputs["residual"] for s in snaps])
    assert status.size == prediction.size == residual.size == 600
    assert np.all(status[:7] == 3)
    assert np.all(np.isnan(prediction[:7]))
    np.testing.assert_allclose(residual[7:], signals["y"][7:] - prediction[7:], rtol=0, atol=0)
    assert snaps[-1].rejected["delay"] == 7
    assert snaps[-1].time_s == pytest.approx(signals.time[-1])


def test_accept_mask_rejects_both_ends_of_a_delayed_pair() -> None:
    signals = drive()
    accept = np.ones(600, dtype=bool)
    accept[100] = False  # the measurement of step 100 and the input of step 105
    sensor = {"lag": 0.5, "delay_samples": 5, "sigma_f": 0.05}
    final = get_spec("kf").build(config("kf", sensor=sensor)).fit(signals, accept=accept)
    assert final.rejected["mask"] == 2


def test_resume_rejects_a_foreign_state() -> None:
    signals = drive()
    skf_state = get_spec("skf").build(config("skf")).fit(signals).state
    with pytest.raises(StateError, match="'skf' filter cannot resume 'kf'"):
        list(get_spec("kf").build(config("kf")).run(signals, state=skf_state))
    other = config("skf") | {"axes": [{"name": "u1", "breakpoints": [0, 1, 2, 3, 4]}]}
    with pytest.raises(StateError, match="12 cells, the table 5"):
        list(get_spec("skf").build(other).run(signals, state=skf_state))


def test_sensor_delay_in_seconds_needs_a_uniform_time_base() -> None:
    signals = drive()
    uneven = Signals(
        signals.time * np.linspace(1.0, 1.5, 600),
        {k: signals[k] for k in ("u1", "u2", "y")},
    )
    estimator = get_spec("skf").build(config("skf", sensor={"lag": 0.9, "delay_s": 0.1}))
    assert estimator.fit(signals).rejected["delay"] == 5
    with pytest.raises(SignalError, match="not uniformly sampled"):
        estimator.fit(uneven)
    by_samples = get_spec("skf").build(config("skf", sensor={"lag": 0.9, "delay_samples": 5}))
    assert by_samples.fit(uneven).rejected["delay"] == 5


def test_signals_copy_by_default_and_adopt_without_copying_when_asked() -> None:
    """``Signals`` copies its inputs unless a reader hands its columns over (``copy=False``):
    then no copy is made, and the columns become read-only so they cannot change under it."""
    t, u = np.arange(4) * 0.1, np.array([1.0, 2.0, 3.0, 4.0])
    copied = Signals(t, {"u": u})
    assert not np.shares_memory(copied["u"], u)
    u[0] = 9.0  # the caller's array stays writable and the copy does not see it
    assert copied["u"][0] == 1.0
    adopted = Signals(t, {"u": u}, copy=False)
    assert np.shares_memory(adopted["u"], u)
    assert np.shares_memory(adopted.time, t)
    with pytest.raises(ValueError, match="read-only"):
        u[0] = 1.0
    ints = Signals(np.arange(3.0), {"n": np.array([1, 2, 3])}, copy=False)
    assert ints["n"].dtype == np.float64  # a conversion still happens where one is needed
    with pytest.raises(SignalError, match="non-finite"):
        Signals(np.arange(2.0), {"u": np.array([1.0, np.nan])}, copy=False)


SENSOR = {"lag": 0.9, "delay_samples": 5}
BLOCK_CASES = [(name, None) for name in FILTERS] + [("kf", SENSOR), ("skf", SENSOR)]


@pytest.mark.parametrize(("name", "sensor"), BLOCK_CASES)
def test_a_chunk_run_in_regressor_blocks_is_one_kernel_call(
    name: str, sensor: dict[str, object] | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``advance`` makes the regressor a block at a time and carries the kernel state across
    blocks: 7-step blocks give the one-block result bit for bit (map, variance, outputs)."""
    import estimation.filters.estimator as filters

    extra = {} if sensor is None else {"sensor": sensor}
    signals = drive()
    whole = get_spec(name).build(config(name, **extra)).fit(signals)
    monkeypatch.setattr(filters, "REGRESSOR_BLOCK", 7)
    blocks = get_spec(name).build(config(name, **extra)).fit(signals)
    assert np.array_equal(whole.table.values, blocks.table.values)
    if whole.variance is not None:
        assert np.array_equal(whole.variance, blocks.variance)
    for key in whole.outputs:
        assert np.array_equal(whole.outputs[key], blocks.outputs[key], equal_nan=True)
    assert np.array_equal(whole.status, blocks.status)
    assert whole.rejected == blocks.rejected
