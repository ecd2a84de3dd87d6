"""Vehicle/gearbox/driver model and engine-cycle denormalisation (estimation.plants.vehicle)."""

import math
from functools import cache

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation.cycles import load_cycle
from estimation.errors import ConfigError, SignalError
from estimation.plants.engine import DieselEngine
from estimation.plants.vehicle import (
    OperatingPoints,
    ShiftStrategy,
    Vehicle,
    denormalise_engine_cycle,
    drive_trace,
    operating_points,
    whtc_reference_speeds,
)

ENGINE = DieselEngine()
VEHICLE = Vehicle()
VEHICLE_CYCLES = ["udds", "hwfet", "us06", "wltc3b", "nedc", "ftp75", "sdmp"]
KNOWN_DISTANCE_KM = {
    "udds": 11.99, "hwfet": 16.51, "us06": 12.89, "wltc3b": 23.27, "nedc": 11.007, "ftp75": 17.77,
}  # fmt: skip


@cache
def _ops(name: str, rate_hz: float = 10.0) -> OperatingPoints:
    return operating_points(load_cycle(name), rate_hz=rate_hz)


# ------------------------------------------------------------------------- engine maps


def test_fuel_map_hand_values():
    # T_fr(2000) = (0.75 + 0.25·2 + 0.05·4) bar · 2 L / 4π = 23.077 N·m; η_i(2000) = 0.46
    # u = 4π·(200 + 23.077) / (4·0.46·42.8e6) · 1e6 = 35.60 mg/cycle
    assert float(ENGINE.friction_torque(2000.0)) == pytest.approx(23.077, rel=1e-4)
    assert float(ENGINE.fuel_mg_per_cycle(200.0, 2000.0)) == pytest.approx(35.597, rel=1e-4)
    # full load at 2000 rpm (380 N·m) -> 64.32 mg/cycle, inside the SKF NOx grid (0-80)
    assert float(ENGINE.fuel_mg_per_cycle(380.0, 2000.0)) == pytest.approx(64.32, rel=1e-3)
    # idle, no load: T_fr(800) = 15.63 N·m, η_i(800) = 0.46·(1 − 0.03·1.2²) = 0.44013
    assert float(ENGINE.fuel_mg_per_cycle(0.0, 800.0)) == pytest.approx(2.6066, rel=1e-3)
    assert float(ENGINE.fuel_mg_per_cycle(-30.0, 800.0)) == 0.0  # below drag: no fuel
    assert float(ENGINE.full_load_torque(2927.06)) == pytest.approx(362.92, abs=0.01)


def test_whtc_reference_speeds_hand_computed():
    # P_max: on 3500–4000 rpm T = 610 − 0.08 n, P ∝ T·n peaks at n = 3812.5, T = 305 N·m
    # -> 121.77 kW. n_lo (55 %): 0.16 n² + 100 n − 639 500 = 0 on 1500–1750 -> 1711.0 rpm.
    # n_hi (70 %): 0.8 n² − 3600 n + 813 990 = 0 on 4250–4500 -> 4261.2 rpm.
    # n_95h (95 %): 0.36 n² − 1730 n + 1 104 700 = 0 on 4000–4250 -> 4047.4 rpm.
    # ∫T dn from 800 to 4047.4 = 1 073 342 N·m·rpm; 51 % = 547 404, reached 96/380 rpm
    # before 2500 (∫ to 2500 = 547 500) -> n_pref = 2499.75 rpm.
    ref = whtc_reference_speeds(ENGINE)
    assert ref.n_lo == pytest.approx(1711.0, abs=1.0)
    assert ref.n_hi == pytest.approx(4261.2, abs=1.0)
    assert ref.n_95h == pytest.approx(4047.4, abs=1.0)
    assert ref.n_pref == pytest.approx(2499.75, abs=1.0)


def test_whtc_denormalisation_hand_points():
    # n_ref = 0.45·1711.0 + 0.45·2499.75 + 0.1·4261.2 = 2320.96 rpm
    # n = n_norm·(2320.96 − 800)·2.0327 + 800 = n_norm·3091.65 + 800
    op = denormalise_engine_cycle(load_cycle("whtc"), rate_hz=10.0)
    k = {t: 10 * t for t in (8, 30, 476)}
    # t = 8 s: 15.8 %, 30.9 % -> 1288.5 rpm, 0.309·T_max(1288.5) = 0.309·289.24 = 89.37 N·m
    assert op.speed_rpm[k[8]] == pytest.approx(1288.48, rel=2e-3)
    assert op.torque_nm[k[8]] == pytest.approx(89.37, rel=2e-3)
    # t = 30 s: 52.1 %, motoring -> 2410.8 rpm, −T_fr = −1.6433 bar·2 L/4π = −26.15 N·m, no fuel
    assert op.speed_rpm[k[30]] == pytest.approx(2410.75, rel=2e-3)
    assert op.torque_nm[k[30]] == pytest.approx(-26.15, rel=2e-3)
    assert op.fuel_mg_per_cycle[k[30]] == 0.0
    # t = 476 s: 68.8 %, 100 % -> 2927.1 rpm on the full-load curve: 362.9 N·m
    assert op.speed_rpm[k[476]] == pytest.approx(2927.06, rel=2e-3)
    assert op.torque_nm[k[476]] == pytest.approx(362.92, rel=2e-3)
    assert op.fuel_mg_per_cycle[k[476]] > 60.0
    assert_array_equal(op.gear, 0)
    assert op.vehicle_speed_kmh is None


def test_whtc_motoring_has_no_fuel_and_drag_torque():
    op = _ops("whtc")
    motoring = op.torque_nm < 0
    assert motoring.mean() > 0.15
    assert_array_equal(op.fuel_mg_per_cycle[motoring], 0.0)
    assert np.all(op.torque_nm >= -ENGINE.friction_torque(op.speed_rpm) - 1e-9)
    assert np.all(op.torque_nm <= ENGINE.full_load_torque(op.speed_rpm) + 1e-9)
    assert ENGINE.idle_speed_rpm <= op.speed_rpm.min()
    assert op.speed_rpm.max() <= ENGINE.rated_speed_rpm


# ------------------------------------------------------------------------ hand-made traces


def _steady_check(speed_kmh: float, grade_pct: float) -> None:
    t = np.arange(61.0)
    op = drive_trace(t, np.full(t.size, speed_kmh), grade_pct=np.full(t.size, grade_pct))
    v = speed_kmh / 3.6
    theta = math.atan(grade_pct / 100)
    m = VEHICLE.mass_kg
    force_n = m * 9.81 * (0.010 * math.cos(theta) + math.sin(theta)) + 0.5 * 1.2 * 0.66 * v**2
    gear = op.gear[-1]
    assert_array_equal(op.gear, gear)  # rolling steadily: engaged from the start, no shifts
    ratio = VEHICLE.gear_ratios[gear - 1] * 3.55
    n_rpm = v / 0.31 * ratio * 30 / math.pi
    assert_allclose(op.speed_rpm, n_rpm, rtol=1e-9)
    # power balance: T_e·ω_e·η = F·v
    assert_allclose(op.torque_nm * n_rpm * math.pi / 30 * 0.93, force_n * v, rtol=1e-9)
    assert_allclose(op.fuel_mg_per_cycle, ENGINE.fuel_mg_per_cycle(op.torque_nm, n_rpm))


def test_steady_cruise_100_kmh_flat_is_6th_gear_power_balance():
    # F = 0.01·1600·9.81 + ½·1.2·0.66·27.78² = 462.6 N; 6th: 1883 rpm, T_e = 70.1 N·m
    _steady_check(100.0, 0.0)
    op = drive_trace(np.arange(61.0), np.full(61, 100.0))
    assert_array_equal(op.gear, 6)
    assert op.speed_rpm[0] == pytest.approx(1883.0, abs=1.0)
    assert op.torque_nm[0] == pytest.approx(70.1, abs=0.1)


def test_steady_climb_power_balance():
    _steady_check(60.0, 6.0)


def test_coast_down_cuts_fuel_and_motors():
    # 100 -> 50 km/h at −1.5 m/s² (5.4 km/h per s): inertia −2520 N beats road load ≤ 463 N
    v = np.concatenate((np.full(10, 100.0), 100.0 - 5.4 * np.arange(1, 10), np.full(10, 50.0)))
    op = drive_trace(np.arange(v.size, dtype=float), v, rate_hz=50.0)
    braking = (op.time_s > 10.5) & (op.time_s < 17.5)
    assert np.all(op.gear[braking] > 0)
    assert np.all(op.speed_rpm[braking] >= ENGINE.fuel_cut_min_rpm)
    assert_array_equal(op.fuel_mg_per_cycle[braking], 0.0)
    assert_allclose(op.torque_nm[braking], -ENGINE.friction_torque(op.speed_rpm[braking]))
    assert np.all(op.fuel_mg_per_cycle[op.time_s < 9.0] > 5.0)  # cruising before


def test_standstill_idles_in_neutral():
    v = np.concatenate((np.zeros(10), np.linspace(0, 30, 11)[1:], np.full(10, 30.0), np.zeros(5)))
    v[30:35] = [24.0, 18.0, 12.0, 6.0, 0.0]
    op = drive_trace(np.arange(v.size, dtype=float), v, rate_hz=10.0)
    stopped = op.time_s < 9.0
    assert_array_equal(op.gear[stopped], 0)
    assert_array_equal(op.speed_rpm[stopped], ENGINE.idle_speed_rpm)
    assert_array_equal(op.torque_nm[stopped], 0.0)
    assert_allclose(op.fuel_mg_per_cycle[stopped], 2.6066, rtol=1e-3)
    assert op.gear[op.time_s == 12.0] == 1  # pulling away in 1st
    assert op.gear[-1] == 0
    assert op.speed_rpm[-1] == ENGINE.idle_speed_rpm


# ------------------------------------------------------------------------- every cycle


@pytest.mark.parametrize("name", VEHICLE_CYCLES)
def test_cycle_operating_points_are_physical(name):
    op = _ops(name)
    n, T, u = op.speed_rpm, op.torque_nm, op.fuel_mg_per_cycle
    for arr in (n, T, u, op.vehicle_speed_kmh):
        assert np.all(np.isfinite(arr))
    assert n.min() >= ENGINE.idle_speed_rpm
    assert n.max() <= ENGINE.rated_speed_rpm
    assert np.all(T - ENGINE.full_load_torque(n) <= 1e-9)
    assert np.all(T + ENGINE.friction_torque(n) >= -1e-9)
    assert u.min() >= 0.0
    assert u.max() <= 70.0
    assert_array_equal(u[T < 0], 0.0)  # motoring <=> fuel cut
    fuel_cut = (u == 0.0) & (op.gear > 0)
    assert_allclose(T[fuel_cut], -ENGINE.friction_torque(n[fuel_cut]))
    assert 0.05 < fuel_cut.mean() < 0.5  # overrun happens on every cycle
    assert np.all(op.vehicle_speed_kmh >= 0.0)
    stopped = op.vehicle_speed_kmh < 0.1
    assert_array_equal(op.gear[stopped], 0)
    assert np.all(u[stopped] > 0.0)  # idling, not stalled
    assert np.abs(np.diff(n)).max() * 10.0 <= VEHICLE.shift.speed_slew_rpm_per_s + 1e-6
    assert set(np.unique(op.gear)) <= set(range(7))


@pytest.mark.parametrize("name", [c for c in VEHICLE_CYCLES if c != "sdmp"])
def test_braking_on_flat_cycles_cuts_fuel(name):
    op = _ops(name)
    a_ms2 = np.gradient(op.vehicle_speed_kmh / 3.6, op.time_s)
    braking = (a_ms2 < -0.8) & (op.gear > 0) & (op.speed_rpm >= ENGINE.fuel_cut_min_rpm + 50)
    assert braking.sum() > 50
    assert_array_equal(op.fuel_mg_per_cycle[braking], 0.0)


@pytest.mark.parametrize("name", list(KNOWN_DISTANCE_KM))
def test_interpolated_trace_keeps_distance_and_samples(name):
    cycle = load_cycle(name)
    op = _ops(name)
    distance_km = float(np.trapezoid(op.vehicle_speed_kmh, op.time_s) / 3600)
    assert distance_km == pytest.approx(KNOWN_DISTANCE_KM[name], rel=0.01)
    assert_allclose(op.vehicle_speed_kmh[::10], cycle.speed_kmh, atol=1e-9)  # hits the knots
    assert op.time_s[-1] == cycle.time_s[-1]


@pytest.mark.parametrize("name", VEHICLE_CYCLES)
def test_no_gear_hunting(name):
    op = _ops(name)
    changes = np.flatnonzero(np.diff(op.gear)) + 1
    t_change = op.time_s[changes]
    before, after = op.gear[changes - 1], op.gear[changes]
    gear_to_gear = (before > 0) & (after > 0)
    gaps = np.diff(t_change)[gear_to_gear[1:]]
    assert gaps.min() >= VEHICLE.shift.min_gear_time_s - 1e-9
    assert np.all(np.abs(after[gear_to_gear] - before[gear_to_gear]) == 1)
    # fewer than one gear change every 4 s on average
    assert changes.size < op.time_s[-1] / 4.0


def test_no_nan_on_any_cycle_at_50_hz():
    for name in [*VEHICLE_CYCLES, "whtc"]:
        sig = _ops(name, 50.0).to_signals()  # Signals rejects non-finite values
        assert sig.sample_period() == pytest.approx(0.02)


def test_full_cycle_is_repeatable():
    """Its speed is `mapwise bench --section simulators`, not a wall-clock assert."""
    cycle = load_cycle("wltc3b")
    first = operating_points(cycle, rate_hz=50.0)  # compile / load the numba cache
    again = operating_points(cycle, rate_hz=50.0)
    np.testing.assert_array_equal(first.fuel_mg_per_cycle, again.fuel_mg_per_cycle)


def test_sdmp_is_harsher_than_nedc():
    sdmp, nedc = _ops("sdmp"), _ops("nedc")
    # sharp load changes: fuel rate of change and high-load share much larger on the SDMP
    du_sdmp = np.percentile(np.abs(np.diff(sdmp.fuel_mg_per_cycle)), 99)
    du_nedc = np.percentile(np.abs(np.diff(nedc.fuel_mg_per_cycle)), 99)
    assert du_sdmp > 2.0 * du_nedc
    assert np.mean(sdmp.fuel_mg_per_cycle > 40.0) > 5.0 * np.mean(nedc.fuel_mg_per_cycle > 40.0)
    assert sdmp.speed_rpm.max() > 3000.0


# ------------------------------------------------------------------------ output and errors


def test_to_signals_channels_and_units():
    op = _ops("nedc")
    sig = op.to_signals()
    assert sig.names == ["speed_rpm", "torque_nm", "fuel_mg_per_cycle", "gear", "vehicle_speed_kmh"]
    assert sig.units == {
        "speed_rpm": "rpm", "torque_nm": "N·m", "fuel_mg_per_cycle": "mg/cycle", "gear": "-",
        "vehicle_speed_kmh": "km/h",
    }  # fmt: skip
    assert_array_equal(sig["gear"], op.gear.astype(float))
    assert "vehicle_speed_kmh" not in _ops("whtc").to_signals()
    with pytest.raises(ValueError, match="read-only"):
        op.speed_rpm[0] = 0.0


def test_errors():
    whtc, udds = load_cycle("whtc"), load_cycle("udds")
    with pytest.raises(ConfigError, match="'udds' is a vehicle cycle"):
        denormalise_engine_cycle(udds)
    with pytest.raises(ConfigError, match=r"rate_hz must be a finite number >= 1 Hz, got 0\.5"):
        operating_points(whtc, rate_hz=0.5)
    with pytest.raises(SignalError, match="speed_kmh must be >= 0, got -1"):
        drive_trace([0.0, 1.0, 2.0], [0.0, -1.0, 0.0])
    with pytest.raises(SignalError, match="strictly increasing"):
        drive_trace([0.0, 2.0, 1.0], [0.0, 1.0, 0.0])
    with pytest.raises(ConfigError, match="strictly decreasing"):
        Vehicle(gear_ratios=(3.8, 4.0))
    with pytest.raises(ConfigError, match=r"downshift \+ hysteresis \(2200\) < upshift_light"):
        ShiftStrategy(downshift_rpm=2000.0, hysteresis_rpm=200.0)
    with pytest.raises(ConfigError, match=r"idle \(900.0\) < rated \(800.0\)"):
        DieselEngine(idle_speed_rpm=900.0, rated_speed_rpm=800.0)
    with pytest.raises(ConfigError, match="must not exceed rated speed"):
        drive_trace(udds.time_s, udds.speed_kmh, engine=DieselEngine(rated_speed_rpm=3500.0))


def test_pchip_matches_scipy_inside_and_never_overshoots():
    from estimation.plants.vehicle import _pchip

    rng = np.random.default_rng(0)
    x = np.arange(40.0)
    y = np.maximum(np.cumsum(rng.normal(0.0, 3.0, x.size)), 0.0)
    xq = np.linspace(0.0, 39.0, 3901)
    yq, dyq = _pchip(x, y, xq)
    k = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, x.size - 2)
    lo, hi = np.minimum(y[k], y[k + 1]), np.maximum(y[k], y[k + 1])
    assert np.all((yq >= lo - 1e-12) & (yq <= hi + 1e-12))  # monotone per interval
    assert_allclose(yq[::100], y, atol=1e-12)
    assert_allclose(np.gradient(yq, xq)[1:-1], dyq[1:-1], atol=0.05 * np.abs(dyq).max())
    import scipy.interpolate as interpolate  # scipy comes with cvxpy and the solvers

    inner = (xq >= 1.0) & (xq <= 38.0)  # end slopes differ by design (secant vs 3-point)
    ref = interpolate.PchipInterpolator(x, y)
    assert_allclose(yq[inner], ref(xq[inner]), atol=1e-9)
    assert_allclose(dyq[inner], ref(xq[inner], 1), atol=1e-9)
