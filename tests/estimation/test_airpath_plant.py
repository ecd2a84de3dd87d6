"""Tests of the diesel air-path simulator (W&E 2011 model, LPV (1)–(3), (7), EKF (6))."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation.cycles import load_cycle
from estimation.errors import ConfigError, ShapeError
from estimation.kernels import airpath_plant as apk
from estimation.plants.airpath import actuator_feedforward, simulate_airpath
from estimation.plants.airpath_params import ActuatorSchedule, AirpathParams, AirpathScaling
from estimation.plants.airpath_rho import lpv_rhs, rho_from_measurements
from estimation.plants.airpath_sensors import MafErrorSpec, NoiseSpec, default_maf_error_2d
from estimation.plants.vehicle import operating_points
from estimation.table import Axis, Table


def steady(fuel: float, speed: float, *, egr: float | None = None, vgt: float | None = None,
           duration_s: float = 40.0, **kw):  # fmt: skip
    """Hold the inputs and return the truth (the last sample is the steady state)."""
    t = np.array([0.0, duration_s])
    extra = {} if egr is None else {"egr_pct": [egr, egr], "vgt_pct": [vgt, vgt]}
    return simulate_airpath(
        t, [fuel, fuel], [speed, speed], seed=0, noise=NoiseSpec.off(), **extra, **kw
    )


def random_steps(duration_s: float, *, seed: int, hold_s: float = 5.0, ramp_s: float = 1.0):
    """Random steps of (u_δ, n_e) over the whole range, ramped over ``ramp_s``."""
    rng = np.random.default_rng(seed)
    n_seg = int(duration_s / hold_s)
    t = np.arange(n_seg + 1) * hold_s
    fuel = rng.uniform(0.0, 56.0, n_seg)
    speed = rng.uniform(700.0, 3500.0, n_seg)
    tt = np.column_stack([t[:-1], t[1:] - ramp_s]).ravel()
    return tt, np.repeat(fuel, 2), np.repeat(speed, 2)


def whtc_2l():
    """WHTC denormalised to the ~2 L engine (idle 800 rpm, top 2950 rpm, full load 56 mg)."""
    whtc = load_cycle("whtc")
    tq = np.clip(whtc.torque_pct, 0.0, None)  # motoring (−100 %) injects no fuel
    return whtc.time_s, 56.0 * tq / 100.0, 800.0 + 21.5 * whtc.speed_pct


# --------------------------------------------------------------------------- steady state


@pytest.mark.parametrize(("fuel", "speed"), [(5.0, 900.0), (20.0, 1500.0), (40.0, 2500.0),
                                             (56.0, 2000.0), (10.0, 3200.0)])  # fmt: skip
def test_steady_state_mass_and_power_balances(fuel: float, speed: float) -> None:
    _, tr = steady(fuel, speed, duration_s=60.0)
    w_c, w_egr, w_ei = tr["w_c_kg_s"][-1], tr["w_egr_kg_s"][-1], tr["w_ei_kg_s"][-1]
    w_f, w_t = tr["w_f_kg_s"][-1], tr["w_t_kg_s"][-1]
    # intake: W_c + W_egr = W_ei ; exhaust: W_ei + W_f = W_egr + W_t  (LPV (1))
    assert_allclose(w_c + w_egr, w_ei, rtol=1e-6)
    assert_allclose(w_ei + w_f, w_egr + w_t, rtol=1e-6)
    # turbo: P_t η_m = P_c
    assert_allclose(tr["p_t_eta_m_w"][-1], tr["p_c_w"][-1], rtol=1e-5)
    assert tr.clamp_events == 0
    # the fuel flow is LPV (2)'s W_f = 1e-6/120 n_cyl n_e u_δ
    assert_allclose(w_f, 1e-6 / 120 * 4 * speed * tr["fuel_mg_per_cycle"][-1], rtol=1e-12)


def test_steady_state_is_reached_and_plausible() -> None:
    _, tr = steady(40.0, 2500.0, duration_s=60.0)
    assert abs(tr["dp_im_pa_s"][-1]) < 1.0  # Pa/s
    assert abs(tr["domega_t_rad_s2"][-1]) < 1.0
    assert 1.5e5 < tr["p_im_pa"][-1] < 3.0e5
    assert 600.0 < tr["t_em_k"][-1] < 1000.0
    assert 1.2 <= tr["lambda_o"][-1] < 3.0


# --------------------------------------------------------------------------- monotonicity


def test_more_fuel_raises_exhaust_pressure_turbo_speed_and_air_flow() -> None:
    res = [steady(f, 2000.0, egr=20.0, vgt=50.0)[1] for f in (10.0, 20.0, 35.0, 50.0)]
    for name in ("p_em_pa", "omega_t_rad_s", "w_c_kg_s", "p_im_pa", "t_em_k"):
        values = [tr[name][-1] for tr in res]
        assert np.all(np.diff(values) > 0), (name, values)


def test_closing_the_vgt_raises_exhaust_pressure_and_boost() -> None:
    res = [steady(30.0, 2000.0, egr=0.0, vgt=v)[1] for v in (90.0, 70.0, 50.0, 35.0)]
    for name in ("p_em_pa", "p_im_pa", "omega_t_rad_s"):
        values = [tr[name][-1] for tr in res]
        assert np.all(np.diff(values) > 0), (name, values)


def test_opening_the_egr_valve_raises_egr_flow_and_lowers_fresh_air() -> None:
    res = [steady(15.0, 1800.0, egr=e, vgt=50.0)[1] for e in (0.0, 20.0, 40.0, 60.0)]
    w_egr = [tr["w_egr_kg_s"][-1] for tr in res]
    w_c = [tr["w_c_kg_s"][-1] for tr in res]
    assert w_egr[0] == 0.0
    assert np.all(np.diff(w_egr) > 0), w_egr
    assert np.all(np.diff(w_c) < 0), w_c


# --------------------------------------------------------------------------- LPV structure


def test_lpv_model_reproduces_the_plant_derivatives() -> None:
    t, fuel, speed = random_steps(200.0, seed=3)
    _, tr = simulate_airpath(t, fuel, speed, seed=0, noise=NoiseSpec.off(), rate_hz=20.0)
    x = np.column_stack([tr["p_im_pa"], tr["p_em_pa"], tr["omega_t_rad_s"]])
    dx = np.column_stack([tr["dp_im_pa_s"], tr["dp_em_pa_s"], tr["domega_t_rad_s2"]])
    J_t = tr.params.J_t
    exact = lpv_rhs(x, tr.rho, tr["w_f_kg_s"], tr["p_t_eta_m_w"], a1=tr.a1, a2=tr.a2(), J_t=J_t)
    scale = np.max(np.abs(dx), axis=0)
    # with the time-varying a2(T_em) the LPV form is an identity of the model
    assert_allclose(exact, dx, rtol=0, atol=1e-9 * scale.max())
    # ρ of LPV (3) are the flow ratios W_c/ω_t, W_egr/p_em, W_ei/p_im, W_t/p_em, P_c/(J ω²)
    assert_allclose(tr.rho[:, 0], tr["w_c_kg_s"] / x[:, 2], rtol=1e-12)
    assert_allclose(tr.rho[:, 1], tr["w_egr_kg_s"] / x[:, 1], rtol=1e-12, atol=1e-20)
    assert_allclose(tr.rho[:, 2], tr["w_ei_kg_s"] / x[:, 0], rtol=1e-12)
    assert_allclose(tr.rho[:, 3], tr["w_t_kg_s"] / x[:, 1], rtol=1e-12)
    assert_allclose(tr.rho[:, 4], tr["p_c_w"] / (J_t * x[:, 2] ** 2), rtol=1e-10)
    # with docs/algorithms.md §3's constant a2 only the p_em row is off, in proportion to
    # the spread of T_em: report how close (here < 60 % of the row's RMS)
    const = lpv_rhs(x, tr.rho, tr["w_f_kg_s"], tr["p_t_eta_m_w"], a1=tr.a1, a2=tr.a2_nominal,
                    J_t=J_t)  # fmt: skip
    assert_allclose(const[:, [0, 2]], dx[:, [0, 2]], rtol=0, atol=1e-9 * scale.max())
    rel = np.sqrt(np.mean((const[:, 1] - dx[:, 1]) ** 2) / np.mean(dx[:, 1] ** 2))
    t_spread = np.std(tr["t_em_k"]) / np.mean(tr["t_em_k"])
    assert 0.0 < rel < 0.6
    assert t_spread > 0.05


def test_rho_from_measurements_matches_truth_without_noise() -> None:
    t, fuel, speed = random_steps(100.0, seed=4)
    sig, tr = simulate_airpath(t, fuel, speed, seed=0, noise=NoiseSpec.off())
    rho_sig = sig.stack([f"rho{i}" for i in range(1, 6)])
    # the plant iterates (T_1, x_r) once per step, the signals to convergence: tiny gap
    assert_allclose(rho_sig[:, 1:], tr.rho[:, 1:], rtol=2e-3, atol=1e-12)
    assert_allclose(sig["rho1_compressor"], tr.rho[:, 0], rtol=2e-3)
    assert_allclose(sig["w_egr_kg_s"], tr["w_egr_kg_s"], rtol=2e-3, atol=1e-9)
    measured = (
        sig["p_im_pa"], sig["p_em_pa"], sig["omega_t_rad_s"], sig["u_egr_pos_pct"],
        sig["u_vgt_pos_pct"], sig["fuel_mg_per_cycle"], sig["speed_rpm"],
    )  # fmt: skip
    rho2, t_em, _ = rho_from_measurements(*measured, time_s=sig.time, params=tr.params)
    assert_array_equal(rho2, rho_sig)
    assert_allclose(t_em, tr["t_em_k"], rtol=2e-3)
    rho_c, _, _ = rho_from_measurements(*measured, rho1_model="compressor", params=tr.params)
    assert_array_equal(rho_c[:, 0], sig["rho1_compressor"])
    assert_array_equal(rho_c[:, 1:], rho_sig[:, 1:])
    # manifold ρ1 = (ρ3 p_im − ρ2 p_em + ṗ_im/a1)/ω_t (LPV (1), first row), ṗ backward
    p, pe, w = sig["p_im_pa"], sig["p_em_pa"], sig["omega_t_rad_s"]
    dp = np.diff(p) / np.diff(sig.time)
    dp = np.concatenate([dp[:1], dp])
    by_hand = (rho_sig[:, 2] * p - rho_sig[:, 1] * pe + dp / tr.a1) / w
    assert_allclose(rho_sig[:, 0], by_hand, rtol=1e-12)
    # with the exact derivative it is an identity of the plant; the difference costs little
    exact = (tr.rho[:, 2] * p - tr.rho[:, 1] * pe + tr["dp_im_pa_s"] / tr.a1) / w
    assert_allclose(exact, tr.rho[:, 0], rtol=1e-9)
    rel = (rho_sig[:, 0] - tr.rho[:, 0]) / tr.rho[:, 0]
    assert np.sqrt(np.mean(rel**2)) < 0.01
    with pytest.raises(ConfigError, match="time_s is needed"):
        rho_from_measurements(*measured)
    with pytest.raises(ConfigError, match="rho1_model"):
        rho_from_measurements(*measured, time_s=sig.time, rho1_model="map")  # type: ignore[arg-type]


@pytest.mark.parametrize("n_iter", [1, 2, 12])
def test_rho_kernel_gives_the_bits_of_the_whole_algebra_iterated(n_iter: int) -> None:
    """The kernel iterates only the Seiliger part (``exhaust_iterate``) before its last
    iteration; the same as evaluating every sub-model each time, as a plain loop does here."""
    t, fuel, speed = random_steps(40.0, seed=5)
    sig, tr = simulate_airpath(t, fuel, speed, seed=1)  # measured: noisy sensors
    names = ("p_im_pa", "p_em_pa", "omega_t_rad_s", "u_egr_pos_pct", "u_vgt_pos_pct",
             "fuel_mg_per_cycle", "speed_rpm")  # fmt: skip
    cols = [np.ascontiguousarray(sig[name][::7]) for name in names]
    prm = tr.params.to_vector()
    n = cols[0].size
    rho, t_em, w_egr = np.empty((n, 5)), np.empty(n), np.empty(n)
    apk.airpath_rho_kernel(*cols, n_iter, prm, rho, t_em, w_egr)
    alg, expected = np.empty(apk.N_ALG), np.empty((n, 5))
    for k in range(n):
        t1, xr = prm[apk.T_IM], 0.0
        for _ in range(n_iter):
            apk.airpath_algebra(*(c[k] for c in cols), t1, xr, prm, alg)
            t1, xr = alg[apk.A_T1_NEW], alg[apk.A_XR_NEW]
        apk.rho_from_algebra(cols[0][k], cols[1][k], cols[2][k], prm, alg, expected[k])
        assert t_em[k] == alg[apk.A_T_EM]
        assert w_egr[k] == alg[apk.A_W_EGR]
    assert rho.tobytes() == expected.tobytes()
    with pytest.raises(ConfigError, match="n_iter"):
        rho_from_measurements(*cols, time_s=np.arange(n) * 0.7, params=tr.params, n_iter=0)


def test_manifold_rho1_is_well_conditioned_where_the_compressor_map_is_not() -> None:
    """Under pressure noise the compressor-map ρ1 (LPV (3) literally) is biased by more than
    the MAF error to be found; the intake-manifold balance is not (see rho_from_measurements)."""
    t, fuel, speed = whtc_2l()
    for readings, comp_bias, mani_bias in ((1, 2.0e-3, 0.1e-3), (10, 0.4e-3, 0.02e-3)):
        noise = NoiseSpec(averaged_readings=readings)
        sig, tr = simulate_airpath(t, fuel, speed, seed=0, noise=noise, reuse_plant_run=True)
        w_c = tr["w_c_kg_s"]
        e_comp = sig["rho1_compressor"] * sig["omega_t_rad_s"] - w_c
        e_mani = sig["rho1"] * sig["omega_t_rad_s"] - w_c
        map_size = np.mean(np.abs(tr.maf_error_kg_s))
        assert np.mean(e_comp) > comp_bias  # kg/s, always positive (sqrt, restriction flow)
        assert np.mean(e_comp) > 0.5 * map_size
        assert abs(np.mean(e_mani)) < mani_bias
        assert np.std(e_mani) < 0.25 * np.std(e_comp)
        assert np.all(sig["rho1"] > 0.0)
        if readings == 1:  # the compressor map even reports no flow at all, now and then
            assert np.mean(sig["rho1_compressor"] == 0.0) > 0.01


def test_rho_ranges_are_of_the_order_of_lpv_table_1() -> None:
    t, fuel, speed = random_steps(600.0, seed=5)
    _, tr = simulate_airpath(t, fuel, speed, seed=0, noise=NoiseSpec.off())
    lo, hi = tr.rho.min(axis=0), tr.rho.max(axis=0)
    # LPV Table 1 (ETC): ρ1 [19,150]e-7, ρ2 [-1.65,1.6]e-7, ρ3 [1.09,6.4]e-7,
    # ρ4 [0.61,6.01]e-7, ρ5 [0,3.15]; "same order" = within a factor 3 of the bounds.
    table_hi = np.array([150e-7, 1.6e-7, 6.4e-7, 6.01e-7, 3.15])
    assert np.all(hi < 3.0 * table_hi), hi
    assert np.all(hi[[0, 2, 3, 4]] > table_hi[[0, 2, 3, 4]] / 3.0), hi
    assert hi[1] > 0.3e-7  # the EGR valve is used
    assert lo[0] > 19e-7 / 3, lo
    assert lo[2] > 1.09e-7 / 3, lo
    assert lo[3] > 0.61e-7 / 3, lo
    assert np.all(lo >= 0.0)  # W&E have no reverse EGR flow, so ρ2 ≥ 0 (Table 1 has < 0)


# --------------------------------------------------------------------------- MAF sensor


@pytest.mark.parametrize(
    "spec", [MafErrorSpec.additive_2d(), MafErrorSpec.relative_1d(), MafErrorSpec.none()]
)
def test_measured_maf_minus_injected_error_is_the_true_flow(spec: MafErrorSpec) -> None:
    t, fuel, speed = random_steps(100.0, seed=6)
    sig, tr = simulate_airpath(t, fuel, speed, seed=1, maf_error=spec, noise=NoiseSpec.off())
    assert_allclose(sig["maf_kg_s"] - tr.maf_error_kg_s, tr["w_c_kg_s"], rtol=0, atol=1e-16)
    u = np.column_stack([tr["fuel_mg_per_cycle"], tr["speed_rpm"]])
    if spec.kind == "additive_2d":  # LPV (7): W_meas = W_c + ΔW_c(u_δ, n_e)
        assert_allclose(tr.maf_error_kg_s, spec.table.evaluate(u), rtol=1e-14)
        assert np.max(np.abs(tr.maf_error_kg_s)) > 1e-4
    elif spec.kind == "relative_1d":  # EKF (6): W_meas = (1 + q(W)) W
        q = spec.table.evaluate(tr["w_c_kg_s"][:, None])
        assert_allclose(sig["maf_kg_s"], (1 + q) * tr["w_c_kg_s"], rtol=1e-14)
    else:
        assert_array_equal(sig["maf_kg_s"], tr["w_c_kg_s"])


def test_default_error_map_is_smooth_few_percent_and_on_the_lpv_grid() -> None:
    spec = MafErrorSpec.additive_2d()
    fuel_axis, speed_axis = (a.breakpoints for a in spec.table.axes)
    assert_array_equal(fuel_axis, np.arange(0, 57, 4))
    assert_array_equal(speed_axis, np.arange(0, 3001, 250))
    uu, nn = np.meshgrid(fuel_axis, speed_axis, indexing="ij")
    assert_allclose(spec.table.values, default_maf_error_2d(uu, nn))
    assert 0.5e-3 < np.max(np.abs(spec.table.values)) < 3e-3  # kg/s: a few % of 0.05–0.15
    _, tr = steady(30.0, 2000.0, maf_error=spec)
    rel = abs(tr.maf_error_kg_s[-1]) / tr["w_c_kg_s"][-1]
    assert 0.005 < rel < 0.06


def test_noise_levels_are_as_stated() -> None:
    _, _tr0 = steady(30.0, 2000.0, duration_s=60.0)
    t = np.array([0.0, 60.0])
    sig, tr = simulate_airpath(t, [30.0, 30.0], [2000.0, 2000.0], seed=7, rate_hz=100.0)
    late = tr.time > 30.0
    d_pim = sig["p_im_pa"][late] - tr["p_im_pa"][late]
    d_maf = (sig["maf_kg_s"] - tr["w_c_kg_s"] - tr.maf_error_kg_s)[late]
    d_w = (sig["omega_t_rad_s"] / tr["omega_t_rad_s"] - 1.0)[late]
    assert np.std(d_pim) == pytest.approx(1000.0, rel=0.1)
    assert np.std(d_maf / tr["w_c_kg_s"][late]) == pytest.approx(0.01, rel=0.1)
    assert np.std(d_w) == pytest.approx(0.005, rel=0.1)
    assert_array_equal(sig["speed_rpm"], tr["speed_rpm"])  # default: speed noise off
    # the ECU mean of N readings per logged sample: σ/√N on every channel
    avg, tr10 = simulate_airpath(
        t, [30.0, 30.0], [2000.0, 2000.0], seed=7, rate_hz=100.0,
        noise=NoiseSpec(averaged_readings=10),
    )  # fmt: skip
    assert_array_equal(tr10["p_im_pa"], tr["p_im_pa"])
    assert_allclose(avg["p_im_pa"][late] - tr["p_im_pa"][late], d_pim / np.sqrt(10), rtol=1e-9)
    d_w10 = (avg["omega_t_rad_s"] / tr["omega_t_rad_s"] - 1.0)[late]
    assert np.std(d_w10) == pytest.approx(0.005 / np.sqrt(10), rel=0.1)
    assert NoiseSpec(averaged_readings=10).to_dict()["averaged_readings"] == 10


def test_seeds_reproduce_bit_identically_and_differ_between_seeds() -> None:
    t, fuel, speed = random_steps(60.0, seed=8)
    a, ta = simulate_airpath(t, fuel, speed, seed=123)
    b, tb = simulate_airpath(t, fuel, speed, seed=123)
    c, _ = simulate_airpath(t, fuel, speed, seed=124)
    for name in a.names:
        assert_array_equal(a[name], b[name])
    assert_array_equal(ta.rho, tb.rho)
    assert not np.array_equal(a["maf_kg_s"], c["maf_kg_s"])
    assert_array_equal(ta["w_c_kg_s"], tb["w_c_kg_s"])


# --------------------------------------------------------------------------- robustness


def test_long_random_sweep_is_finite_and_plausible() -> None:
    # Its speed is `mapwise bench --section simulators`, not a wall-clock assert.
    t, fuel, speed = random_steps(1800.0, seed=9)
    sig, tr = simulate_airpath(t, fuel, speed, seed=0)
    assert len(sig) == 17991  # 0 … 1799 s at 10 Hz
    for name, v in tr.channels.items():
        assert np.all(np.isfinite(v)), name
    assert np.all(np.isfinite(tr.rho))
    assert tr.clamp_events == 0
    assert tr["p_im_pa"].min() > 0.95e5
    assert tr["p_im_pa"].max() < 3.5e5
    assert tr["p_em_pa"].min() > 0.95e5
    assert tr["p_em_pa"].max() < 5.0e5
    assert tr["omega_t_rad_s"].min() > 1000.0
    assert tr["omega_t_rad_s"].max() < 22000.0
    assert tr["w_c_kg_s"].min() > 0
    assert tr["w_t_kg_s"].min() > 0
    assert tr["w_egr_kg_s"].min() >= 0
    assert tr["lambda_o"].min() >= 1.2 - 1e-9  # the smoke limiter holds


def test_default_integration_rate_is_converged_where_500_hz_is_not() -> None:
    """The FTP-75 cold start (idle, low boost): Heun at 500 Hz falls into a numerical limit
    cycle of the stiff intake-pressure mode near Π_c ≈ 1; the default 2 kHz agrees with
    8 kHz to a few mg/s."""
    points = operating_points(load_cycle("ftp75"), rate_hz=10.0)
    k = 2001  # 200 s
    runs = {
        rate: simulate_airpath(
            points.time_s[:k], points.fuel_mg_per_cycle[:k], points.speed_rpm[:k], seed=0,
            noise=NoiseSpec.off(), internal_rate_hz=rate,
        )[1]
        for rate in (500.0, 2000.0, 8000.0)
    }  # fmt: skip
    ref = runs[8000.0]

    def rms(a: np.ndarray) -> float:
        return float(np.sqrt(np.mean(a**2)))

    assert rms(runs[2000.0]["w_c_kg_s"] - ref["w_c_kg_s"]) < 1e-5  # kg/s
    assert rms(runs[2000.0]["p_im_pa"] - ref["p_im_pa"]) < 5.0  # Pa
    assert rms(runs[500.0]["w_c_kg_s"] - ref["w_c_kg_s"]) > 2e-4


def test_reused_plant_runs_are_identical_and_independent_of_the_seed() -> None:
    t, fuel, speed = random_steps(60.0, seed=10)
    a, ta = simulate_airpath(t, fuel, speed, seed=1, reuse_plant_run=True)
    ta.channels["w_c_kg_s"][:] = 0.0  # a caller scribbling on its copy changes nothing
    b, tb = simulate_airpath(t, fuel, speed, seed=2, reuse_plant_run=True)
    c, tc = simulate_airpath(t, fuel, speed, seed=2)
    assert_array_equal(tb["w_c_kg_s"], tc["w_c_kg_s"])
    assert tb["w_c_kg_s"].min() > 0.0
    for name in b.names:
        assert_array_equal(b[name], c[name])
    assert not np.array_equal(a["p_im_pa"], b["p_im_pa"])


def test_whtc_cycle_is_physically_plausible() -> None:
    t, fuel, speed = whtc_2l()
    # the plant run of test_manifold_rho1_…, reused (bit-identical: test_reused_plant_runs_…)
    _sig, tr = simulate_airpath(t, fuel, speed, seed=0, reuse_plant_run=True)
    assert tr.clamp_events == 0
    assert tr["p_im_pa"].min() > 0.98e5
    assert tr["p_im_pa"].max() < 3.5e5
    assert tr["p_em_pa"].min() > 0.98e5
    assert tr["p_em_pa"].max() < 3.5e5
    assert tr["omega_t_rad_s"].max() < 22000.0
    assert tr["t_em_k"].min() > 300.0
    assert tr["t_em_k"].max() < 1150.0
    lo, hi = tr.rho.min(axis=0), tr.rho.max(axis=0)
    assert np.all(hi < np.array([450e-7, 4.8e-7, 19e-7, 18e-7, 9.5])), hi
    assert lo[0] > 6e-7
    assert lo[2] > 0.3e-7


def test_given_actuator_commands_are_followed_with_the_we_actuator_dynamics() -> None:
    t = np.array([0.0, 1.0, 1.001, 3.0])
    sig, tr = simulate_airpath(
        t, [20.0] * 4, [2000.0] * 4, seed=0, egr_pct=[0, 0, 50, 50], vgt_pct=[80, 80, 40, 40],
        rate_hz=1000.0, internal_rate_hz=1000.0, noise=NoiseSpec.off(),
    )  # fmt: skip
    pos_vgt = tr["u_vgt_pos_pct"]
    k_step = np.searchsorted(tr.time, 1.001)
    # dead time τ_dvgt = 40 ms, then a first-order lag τ_vgt = 25 ms (W&E)
    assert pos_vgt[k_step + 35] == pytest.approx(80.0, abs=0.05)
    k63 = k_step + 40 + 25
    assert pos_vgt[k63] == pytest.approx(80.0 - 40.0 * (1 - np.exp(-1.0)), abs=1.0)
    # EGR overshoot: K_egr = 1.8 with τ_egr1 < τ_egr2 overshoots the 50 % command
    assert tr["u_egr_pos_pct"].max() > 55.0
    assert tr["u_egr_pos_pct"][-1] == pytest.approx(50.0, abs=0.1)
    assert_array_equal(sig["u_vgt_pct"][tr.time > 1.01], 40.0)


# --------------------------------------------------------------------------- API


def test_truth_to_dict_is_json_serialisable() -> None:
    _, tr = steady(20.0, 1500.0, duration_s=2.0)
    d = json.loads(json.dumps(tr.to_dict()))
    assert d["maf_error"]["kind"] == "additive_2d"
    assert [a["name"] for a in d["maf_error"]["table"]["axes"]] == [
        "fuel_mg_per_cycle",
        "speed_rpm",
    ]
    assert len(d["rho"]) == len(d["time"]) == 21
    assert d["params"]["V_d"] == pytest.approx(0.002)


def test_scaling_rules() -> None:
    ref = AirpathParams.scania()
    p = AirpathParams.scaled(AirpathScaling(turbo_scale=0.5, turbine_area_factor=1.0))
    assert p.V_d == 0.002
    assert p.n_cyl == 4
    assert p.V_im / ref.V_im == pytest.approx(0.002 / 0.01274)
    assert p.R_c == pytest.approx(0.02)
    assert p.A_vgtmax == pytest.approx(ref.A_vgtmax / 4)
    # the compressor map at ω is the Scania map at s·ω (equal tip speed)
    w = 12000.0
    assert p.c_wphi1 * w**2 + p.c_wphi2 * w + p.c_wphi3 == pytest.approx(
        ref.c_wphi1 * (w / 2) ** 2 + ref.c_wphi2 * (w / 2) + ref.c_wphi3
    )
    assert len(p.to_vector()) == apk.N_PARAMS
    # the parameter file's turbine-efficiency constants are continuous at ω_tlin
    assert ref.c_m1 * (ref.w_tlin - ref.c_m2) ** ref.c_m3 == pytest.approx(ref.c_mlin, rel=1e-6)


def test_feedforward_schedule() -> None:
    egr, vgt, dp = actuator_feedforward([0.0, 16.0, 40.0, 56.0], [1500.0] * 4)
    assert egr[0] > egr[1] > egr[2] == 0.0
    assert vgt[0] == 100.0
    assert np.all(np.diff(vgt) < 0)
    assert dp[0] == 0.0
    assert np.all(np.diff(dp) > 0)
    with pytest.raises(ConfigError, match="vgt_min_pct"):
        ActuatorSchedule(vgt_min_pct=90.0, vgt_max_pct=50.0)


def test_input_validation() -> None:
    t = np.array([0.0, 1.0])
    with pytest.raises(ConfigError, match=r"speed_rpm must be in \[300, 5000\], got 0"):
        simulate_airpath(t, [10.0, 10.0], [0.0, 1000.0], seed=0)
    with pytest.raises(ConfigError, match="strictly increasing"):
        simulate_airpath(np.array([0.0, 0.0]), [10.0, 10.0], [900.0, 900.0], seed=0)
    with pytest.raises(ShapeError, match="fuel_mg_per_cycle has 3 samples"):
        simulate_airpath(t, [10.0, 10.0, 1.0], [900.0, 900.0], seed=0)
    with pytest.raises(ConfigError, match="both egr_pct and vgt_pct"):
        simulate_airpath(t, [10.0, 10.0], [900.0, 900.0], seed=0, egr_pct=[0.0, 0.0])
    with pytest.raises(ConfigError, match="whole number"):
        simulate_airpath(t, [10.0, 10.0], [900.0, 900.0], seed=0, rate_hz=3.0)
    with pytest.raises(ConfigError, match="needs a 2-D table"):
        MafErrorSpec("additive_2d", Table([Axis("maf_kg_s", "kg/s", [0.0, 0.1])], 0.0))
    with pytest.raises(ConfigError, match=r"NoiseSpec\.maf_rel"):
        NoiseSpec(maf_rel=-0.1)
    for bad in (0, 2.5, True):
        with pytest.raises(ConfigError, match=r"NoiseSpec\.averaged_readings"):
            NoiseSpec(averaged_readings=bad)  # type: ignore[arg-type]
