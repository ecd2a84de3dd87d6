"""NOx ground-truth plant: map shape, drift, sensor delay/lag (SKF (24)–(25), (34)), noise."""

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation import ConfigError, SignalError, Table
from estimation.plants.nox import (
    FUEL_BREAKPOINTS_MG_PER_STROKE,
    NOX_FILTER_CAL_34,
    NOX_FILTER_CAL_36,
    SPEED_BREAKPOINTS_RPM,
    NoxParams,
    drifted_map,
    nox_base_map,
    nox_base_ppm,
    simulate_nox,
)
from estimation.signals import delay_samples

FS_HZ = 50.0
QUIET = NoxParams(noise_std_ppm=0.0)


def _inputs(duration_s: float = 60.0, seed: int = 0) -> tuple[np.ndarray, ...]:
    """A 50 Hz trajectory: smooth sweeps plus random steps, covering the whole grid."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration_s * FS_HZ)) / FS_HZ
    speed = 2600.0 + 1900.0 * np.sin(2 * np.pi * t / 23.0)
    fuel = 40.0 + 40.0 * np.sin(2 * np.pi * t / 7.0) * np.cos(2 * np.pi * t / 31.0)
    steps = np.repeat(rng.uniform(-5.0, 5.0, t.size // 25 + 1), 25)[: t.size]
    fuel = np.clip(fuel + steps, 0.0, 85.0)
    return t, speed, fuel


def _reference_sensor(x: np.ndarray, delay: int, a: float, y_init: float) -> np.ndarray:
    """Slow obvious loop of SKF (25): y(k) = a·y(k−1) + (1−a)·x(k−τ), x(j<0) = x(0)."""
    out = []
    prev = y_init
    for k in range(len(x)):
        xd = x[k - delay] if k - delay >= 0 else x[0]
        prev = a * prev + (1.0 - a) * xd
        out.append(prev)
    return np.array(out)


# --- map ---------------------------------------------------------------------------------


def test_grid_is_skf_34() -> None:
    expected_speed = [750, 780, 1000, 1250, 1500, 1750, *range(2000, 4501, 500)]
    expected_fuel = [*range(0, 31, 5), *range(34, 51, 4), *range(55, 81, 5)]
    assert list(SPEED_BREAKPOINTS_RPM) == expected_speed
    assert list(FUEL_BREAKPOINTS_MG_PER_STROKE) == expected_fuel
    table = nox_base_map()
    assert table.shape == (12, 18)
    assert [a.name for a in table.axes] == ["speed_rpm", "fuel_mg_per_stroke"]
    assert [a.unit for a in table.axes] == ["rpm", "mg/stroke"]


def test_map_range_and_shape() -> None:
    values = nox_base_map().values
    assert values.min() >= 0.0
    assert values.max() <= 2000.0
    assert values.max() > 1500.0  # a real diesel full-load level, not a flat map
    # strictly increasing in fuel at every speed
    assert np.all(np.diff(values, axis=1) > 0.0)
    # peak at full load and mid speed (1750–3000 rpm)
    i, j = np.unravel_index(np.argmax(values), values.shape)
    assert j == values.shape[1] - 1
    assert 1750.0 <= SPEED_BREAKPOINTS_RPM[i] <= 3000.0
    # at full load, speed rises then falls
    full_load = values[:, -1]
    assert full_load[0] < full_load[i] > full_load[-1]


def test_map_nodes_are_the_documented_function() -> None:
    table = nox_base_map()
    assert_allclose(table.values[0, 0], 20.0)
    n, m = 2500.0, 50.0
    expected = 20.0 + 1850.0 * (50.0 / 80.0) ** 1.5 * (0.5 + 0.5 * np.exp(-((250.0 / 1250.0) ** 2)))
    assert_allclose(nox_base_ppm(n, m), expected, rtol=1e-14)
    assert_allclose(table.evaluate([[n, m]])[0], expected, rtol=1e-14)


# --- sensor delay and lag ----------------------------------------------------------------


def test_delay_rounding() -> None:
    # 0.75 s at 50 Hz is 37.5 samples; ties round up to 38
    assert delay_samples(0.75, 0.02) == 38
    assert delay_samples(0.75, 0.75 / 37.5 * (1 + 1e-12)) == 38
    assert delay_samples(0.75, 0.75 / 37.5 * (1 - 1e-12)) == 38
    assert delay_samples(0.74, 0.02) == 37
    assert delay_samples(0.0, 0.02) == 0
    with pytest.raises(ConfigError, match="sample period"):
        delay_samples(0.75, 0.0)


def test_lag_delay_equation_matches_slow_loop() -> None:
    t, speed, fuel = _inputs()
    _, truth = simulate_nox(t, speed, fuel, seed=0, params=QUIET)
    assert truth.delay_samples == 38
    ref = _reference_sensor(truth.nox_true_ppm, 38, 0.96, float(truth.nox_true_ppm[0]))
    assert_allclose(truth.nox_sensor_noise_free_ppm, ref, rtol=0.0, atol=1e-12)
    # and the recursion holds sample by sample inside the record
    y, x = truth.nox_sensor_noise_free_ppm, truth.nox_true_ppm
    k = np.arange(38, len(t))
    assert_allclose(y[k], 0.96 * y[k - 1] + 0.04 * x[k - 38], rtol=0.0, atol=1e-12)


def test_sensor_initial_value_option() -> None:
    t, speed, fuel = _inputs(5.0)
    params = NoxParams(noise_std_ppm=0.0, sensor_initial_ppm=0.0)
    _, truth = simulate_nox(t, speed, fuel, seed=0, params=params)
    ref = _reference_sensor(truth.nox_true_ppm, 38, 0.96, 0.0)
    assert_allclose(truth.nox_sensor_noise_free_ppm, ref, rtol=0.0, atol=1e-12)
    assert_allclose(truth.nox_sensor_noise_free_ppm[0], 0.04 * truth.nox_true_ppm[0])


@pytest.mark.parametrize("step_at", [100, 237])
def test_delay_is_exactly_38_samples(step_at: int) -> None:
    t = np.arange(600) / FS_HZ
    speed = np.full(t.size, 2000.0)
    fuel = np.where(np.arange(t.size) < step_at, 10.0, 60.0)
    params = NoxParams(noise_std_ppm=0.0, lag=0.0, drift_gain_per_h=0.0, drift_offset_ppm_per_h=0.0)
    _, truth = simulate_nox(t, speed, fuel, seed=0, params=params)
    x, y = truth.nox_true_ppm, truth.nox_sensor_noise_free_ppm
    assert x[step_at] != x[step_at - 1]
    # with a = 0 the sensor is a pure delay: y(k) = x(k − 38)
    assert_array_equal(y[38:], x[:-38])
    assert_array_equal(y[:38], np.full(38, x[0]))
    assert y[step_at + 37] == x[0]
    assert y[step_at + 38] == x[step_at]


def test_lag_step_response() -> None:
    # a = 0.96: after the delay, the step error decays as a^(j+1)
    t = np.arange(1000) / FS_HZ
    fuel = np.where(np.arange(t.size) < 50, 10.0, 60.0)
    params = NoxParams(noise_std_ppm=0.0, drift_gain_per_h=0.0, drift_offset_ppm_per_h=0.0)
    _, truth = simulate_nox(t, np.full(t.size, 2000.0), fuel, seed=0, params=params)
    x, y = truth.nox_true_ppm, truth.nox_sensor_noise_free_ppm
    j = np.arange(200)
    expected = x[-1] + (x[0] - x[-1]) * 0.96 ** (j + 1)
    assert_allclose(y[50 + 38 + j], expected, rtol=1e-12)


# --- drift -------------------------------------------------------------------------------


def test_drift_truth_is_consistent() -> None:
    t, speed, fuel = _inputs(120.0)
    t = t + 1000.0  # record does not start at zero
    params = NoxParams(drift_gain_per_h=0.5, drift_offset_ppm_per_h=60.0, start_age_h=2.0)
    signals, truth = simulate_nox(t, speed, fuel, seed=1, params=params)
    base = nox_base_map()
    assert truth.base_map == base
    assert truth.map_at(t[0]) == truth.initial_map
    assert truth.map_at(t[-1]) == truth.final_map
    assert_allclose(truth.initial_map.values, 2.0 * base.values + 120.0)  # (1+0.5·2)T + 60·2
    age_end = 2.0 + (t[-1] - t[0]) / 3600.0
    assert_allclose(truth.final_map.values, (1 + 0.5 * age_end) * base.values + 60.0 * age_end)
    assert np.all(truth.final_map.values > truth.initial_map.values)
    # x(k) is the map of time t_k evaluated at u_k
    U = signals.stack(["speed_rpm", "fuel_mg_per_stroke"])
    for k in (0, 1, 777, 3001, len(t) - 1):
        expected = truth.map_at(t[k]).evaluate(U[k : k + 1])[0]
        assert_allclose(truth.nox_true_ppm[k], expected, rtol=1e-13)


def test_no_drift_means_static_map() -> None:
    t, speed, fuel = _inputs(10.0)
    params = NoxParams(drift_gain_per_h=0.0, drift_offset_ppm_per_h=0.0)
    signals, truth = simulate_nox(t, speed, fuel, seed=0, params=params)
    assert truth.initial_map == truth.final_map == nox_base_map()
    U = signals.stack(["speed_rpm", "fuel_mg_per_stroke"])
    assert_array_equal(truth.nox_true_ppm, nox_base_map().evaluate(U))


def test_drifted_map_formula() -> None:
    base = nox_base_map()
    aged = drifted_map(base, 4.0, NoxParams(drift_gain_per_h=0.02, drift_offset_ppm_per_h=3.0))
    assert_allclose(aged.values, 1.08 * base.values + 12.0)


def test_negative_map_rejected() -> None:
    t, speed, fuel = _inputs(10.0)
    with pytest.raises(ConfigError, match="negative"):
        simulate_nox(t, speed, fuel, seed=0, params=NoxParams(drift_offset_ppm_per_h=-1e5))


# --- noise, seeds, outputs ---------------------------------------------------------------


def test_noise_statistics() -> None:
    t, speed, fuel = _inputs(2000.0)  # 100 000 samples
    signals, truth = simulate_nox(t, speed, fuel, seed=3)
    v = signals["nox_ppm"] - truth.nox_sensor_noise_free_ppm
    assert_allclose(v, truth.noise_ppm, atol=1e-9)
    # σ = 25 ppm: std of the sample std ≈ 25/√(2n) ≈ 0.056
    assert abs(v.std() - 25.0) < 0.3
    assert abs(v.mean()) < 0.3  # SE 0.08
    assert abs(np.corrcoef(v[1:], v[:-1])[0, 1]) < 0.02  # white
    _, quiet = simulate_nox(t, speed, fuel, seed=3, params=QUIET)
    assert_array_equal(quiet.noise_ppm, 0.0)


def test_seed_reproduces_bit_identically() -> None:
    t, speed, fuel = _inputs(30.0)
    a, ta = simulate_nox(t, speed, fuel, seed=42)
    b, tb = simulate_nox(t, speed, fuel, seed=42)
    c, _ = simulate_nox(t, speed, fuel, seed=43)
    assert a["nox_ppm"].tobytes() == b["nox_ppm"].tobytes()
    assert ta.nox_sensor_noise_free_ppm.tobytes() == tb.nox_sensor_noise_free_ppm.tobytes()
    assert not np.array_equal(a["nox_ppm"], c["nox_ppm"])


def test_signals_channels_and_units() -> None:
    t, speed, fuel = _inputs(5.0)
    signals, truth = simulate_nox(t, speed, fuel, seed=0)
    assert signals.names == ["speed_rpm", "fuel_mg_per_stroke", "nox_ppm"]
    assert signals.units == {
        "speed_rpm": "rpm",
        "fuel_mg_per_stroke": "mg/stroke",
        "nox_ppm": "ppm",
    }
    assert_array_equal(signals["speed_rpm"], speed)  # inputs are returned undelayed
    assert_array_equal(signals["fuel_mg_per_stroke"], fuel)
    assert_array_equal(signals.time, truth.time_s)
    assert_allclose(truth.sample_period_s, 0.02, rtol=1e-9)
    with pytest.raises(ValueError, match="read-only"):
        truth.nox_true_ppm[0] = 0.0


def test_truth_to_dict_is_json() -> None:
    t, speed, fuel = _inputs(2.0)
    _, truth = simulate_nox(t, speed, fuel, seed=5)
    data = json.loads(json.dumps(truth.to_dict()))
    assert data["delay_samples"] == 38
    assert data["seed"] == 5
    assert data["params"]["lag"] == 0.96
    assert Table.from_dict(data["final_map"]) == truth.final_map
    assert_array_equal(data["nox_true_ppm"], truth.nox_true_ppm)


def test_custom_base_map() -> None:
    t, speed, fuel = _inputs(5.0)
    flat = nox_base_map().with_values(100.0)
    _, truth = simulate_nox(t, speed, fuel, seed=0, params=QUIET, base_map=flat)
    assert_allclose(truth.nox_true_ppm[0], 100.0)
    wrong = Table(flat.axes[::-1], 1.0)
    with pytest.raises(ConfigError, match="axes"):
        simulate_nox(t, speed, fuel, seed=0, base_map=wrong)


# --- validation --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"lag": 1.0}, "lag"),
        ({"lag": -0.1}, "lag"),
        ({"delay_s": -0.1}, "delay_s"),
        ({"noise_std_ppm": -1.0}, "noise_std_ppm"),
        ({"start_age_h": -1.0}, "start_age_h"),
        ({"drift_gain_per_h": float("nan")}, "drift_gain_per_h"),
        ({"sensor_initial_ppm": float("inf")}, "sensor_initial_ppm"),
    ],
)
def test_bad_params(kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        NoxParams(**kwargs)


def test_bad_inputs() -> None:
    t, speed, fuel = _inputs(2.0)
    with pytest.raises(SignalError, match="fuel_mg_per_stroke"):
        simulate_nox(t, speed, fuel - 100.0, seed=0)
    with pytest.raises(SignalError, match="uniformly"):
        simulate_nox(t**1.5, speed, fuel, seed=0)
    with pytest.raises(SignalError, match="samples"):
        simulate_nox(t, speed[:-1], fuel, seed=0)
    with pytest.raises(ConfigError, match="seed"):
        simulate_nox(t, speed, fuel, seed=1.5)  # type: ignore[arg-type]


def test_filter_calibrations_of_the_paper() -> None:
    assert NOX_FILTER_CAL_34.to_dict() == {
        "sigma_v2": 625.0,
        "sigma_w2": 225.0,
        "sigma_f2": 2500.0,
        "lag": 0.96,
        "delay_s": 0.75,
    }
    assert NOX_FILTER_CAL_36.sigma_w2 == 49.0
