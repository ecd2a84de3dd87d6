"""LPV adaptive observer: LMI gain synthesis, kernel, estimator, unvisited-region fill."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation.errors import ConfigError
from estimation.observers.lmi import synthesize_gain
from estimation.observers.lpv import (
    LPV_SPECS,
    LpvConfig,
    LpvObserver,
    LpvState,
    fill_quadratic,
    fill_smooth,
    lpv_run,
    visited_cells,
)
from estimation.signals import Signals
from estimation.table import Axis, Table

A1, A2 = 2.5e7, 4.6e7
RHO_LO = np.array([0.0, 0.0, 1.55e-7, 0.8e-7, 0.0])
RHO_HI = np.array([5.5e-5, 1.3e-7, 5.6e-7, 8.0e-7, 2.1])


def test_feasible_box_gives_hurwitz_closed_loop_at_every_vertex():
    g = synthesize_gain(RHO_LO, RHO_HI, A1, A2)
    assert g.status == "optimal"
    assert g.margin > 0
    assert g.vertices.shape == (32, 5)
    assert g.hurwitz
    assert np.all(g.closed_loop_eigs.real < 0)


def test_bad_eps_and_infeasible_box_error():
    with pytest.raises(ConfigError, match="eps1 \\+ eps2 must be < 2"):
        synthesize_gain(RHO_LO, RHO_HI, A1, A2, eps1=1.5, eps2=0.6)
    lo = RHO_LO.copy()
    lo[3] = 0.0  # ρ2 = ρ4 = 0: p_em unobservable and marginal
    with pytest.raises(ConfigError, match=r"no valid design|infeasible"):
        synthesize_gain(lo, RHO_HI, A1, A2)
    with pytest.raises(ConfigError, match="exceeds upper bound"):
        synthesize_gain(RHO_HI, RHO_LO, A1, A2)


def _signals(n=400, seed=0):
    """A steady-ish synthetic air path consistent with LPV (3): W_c,meas = ρ1 ω + ΔW_c."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    fuel = 20.0 + 10.0 * np.sin(0.05 * t) + rng.uniform(-2, 2, n)
    speed = 1500.0 + 500.0 * np.sin(0.031 * t)
    omega = 8000.0 + 1000.0 * np.sin(0.02 * t)
    rho = np.column_stack(
        [np.full(n, 1e-5), np.full(n, 5e-8), np.full(n, 3e-7), np.full(n, 4e-7), np.full(n, 1.0)]
    )
    dwc = 1e-3 * (1.0 + fuel / 56.0)
    ch = {
        "fuel_mg_per_cycle": fuel,
        "speed_rpm": speed,
        "p_im_pa": 1.5e5 + 1e3 * np.sin(0.02 * t),
        "p_em_pa": np.full(n, 1.8e5),
        "omega_t_rad_s": omega,
        "maf_kg_s": rho[:, 0] * omega + dwc,
        "w_f_kg_s": 1e-6 / 120 * 4 * speed * fuel,
        "t_em_k": np.full(n, 800.0),
    }
    for i in range(5):
        ch[f"rho{i + 1}"] = rho[:, i] * (1 + 0.2 * np.sin(0.01 * (i + 1) * t))
    return Signals(t, ch, {}), dwc


def test_observer_learns_the_error_and_resume_is_bit_identical(tmp_path):
    sig, _ = _signals()
    obs = LPV_SPECS[0].build({})
    full = obs.fit(sig)
    assert full.table is not None
    assert np.all(np.isfinite(full.state.theta))
    residual = full.outputs["residual"]
    assert np.abs(residual[-100:]).mean() < 0.1 * np.abs(residual[:5]).max() + 1e-5
    snaps = list(obs.run(sig, every=137))
    assert_array_equal(snaps[-1].state.theta, full.state.theta)
    half = snaps[0].state
    half.save(tmp_path / "s.npz")
    for restored in (LpvState.load(tmp_path / "s.npz"), LpvState.from_dict(half.to_dict())):
        resumed = list(obs.run(sig, state=restored))[-1]
        assert_array_equal(resumed.state.theta, full.state.theta)
        assert_array_equal(resumed.state.x_hat, full.state.x_hat)


def test_class_and_functions_agree_and_only_active_cells_move():
    sig, _ = _signals(n=50)
    obs = LpvObserver(LpvConfig())
    prep = obs.prepare(sig)
    st0 = obs.initial_state(sig, prep)
    st, *_ = lpv_run(st0, prep, 0, 50, gamma=200.0)
    assert_array_equal(st.theta, obs.fit(sig).state.theta)
    touched = np.unique(prep.idx[1:][prep.w[1:] > 0])
    untouched = np.setdiff1d(np.arange(st.theta.size), touched)
    assert np.all(st.theta[untouched] == 0.0)
    assert np.all(st0.theta == 0.0)  # the input state is not mutated


def test_config_rejects_bad_eps():
    with pytest.raises(ConfigError, match="eps1 \\+ eps2"):
        LPV_SPECS[0].build({"eps1": 1.5, "eps2": 0.6})


def _quadratic_table():
    u = np.arange(0.0, 57.0, 4.0)
    n = np.arange(0.0, 3001.0, 250.0)
    U, N = np.meshgrid(u / 56, n / 3000, indexing="ij")
    vals = 0.3 * U**2 - 0.1 * U + 0.2 * N**2 + 0.05 * N - 0.1 * U * N + 0.01
    return Table([Axis("fuel_mg_per_cycle", "mg", u), Axis("speed_rpm", "rpm", n)], vals)


def test_quadratic_fill_recovers_a_quadratic_surface():
    true = _quadratic_table()
    rng = np.random.default_rng(0)
    visited = rng.random(true.shape) < 0.4
    partial = true.with_values(np.where(visited, true.values, 0.0))
    filled, mask = fill_quadratic(partial, visited)
    assert_array_equal(mask, visited)
    assert_allclose(filled.values, true.values, atol=1e-12)


def test_smooth_fill_is_exact_on_planes_and_respects_bounds():
    u = np.linspace(0, 1, 6)
    n = np.linspace(0, 1, 5)
    U, N = np.meshgrid(u, n, indexing="ij")
    plane = Table([Axis("a", "", u), Axis("b", "", n)], 1.0 + 2 * U - N)
    visited = np.zeros(plane.shape, dtype=bool)
    visited[:3, :3] = True
    filled, mask = fill_smooth(plane, visited, smoothness=1e-3)
    assert_array_equal(mask, visited)
    assert_allclose(filled.values, plane.values, atol=1e-4)
    bounded, _ = fill_smooth(plane, visited, smoothness=1e-3, upper=2.0)
    assert bounded.values.max() <= 2.0 + 1e-6
    assert visited_cells(np.array([0.5, 1.0, 2.0])).tolist() == [False, True, True]
