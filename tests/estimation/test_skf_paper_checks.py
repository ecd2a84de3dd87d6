"""The SKF paper's synthetic checks (SKF §5, docs/algorithms.md §2.7) and the SSKF gain (§2.3).

Grid u1 = [500 1500 2500 3500], u2 = [0 20 40 60], true table all ones, θ0 = 0, P0 = 0,
σv² = σw² = 1. Data from :func:`estimation.plants.synthetic.skf_sim` (its inputs are checked
against the paper's description here).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation.estimator import Snapshot
from estimation.plants.synthetic import skf_sim
from estimation.registry import get_spec
from estimation.signals import Signals
from tests.estimation import reference as ref

CONFIG = {
    "axes": [
        {"name": "u1", "breakpoints": [500, 1500, 2500, 3500]},
        {"name": "u2", "breakpoints": [0, 20, 40, 60]},
    ],
    "output": "y",
    "theta0": 0.0,
    "sigma_w": 1.0,
    "sigma_v": 1.0,
    "p0": 0.0,
}
EXCITED = list(range(4, 12))  # rows u1 = 1500 and 2500 (the paper's elements 5–12)

# Tolerances on the final |θ − 1| (max over the cells the check is about).
SIM1_TOL = {"kf": 1e-6, "skf": 1e-6, "sskf": 1e-2}
SIM2_TOL = 0.05  # KF, SKF on the 8 excited cells after the return sweep
SIM3_TOL = 0.15  # same with noise of amplitude 0.2 (mean error below 0.1)
SSKF_FAILS = 0.3  # SSKF's error stays at least this large in sims 2 and 3


def _run(kind: str, signals: Signals) -> list[Snapshot]:
    config = dict(CONFIG)
    if kind == "sskf":
        del config["p0"]
    return list(get_spec(kind).build(config).run(signals, every=1))


def _errors(snaps: list[Snapshot], cells: list[int] | slice) -> np.ndarray:
    """(n, cells) |θ_k − 1| after every sample."""
    return np.array([np.abs(s.table.values.ravel()[cells] - 1.0) for s in snaps])


def test_sim_inputs_are_the_papers() -> None:
    s1, _ = skf_sim(1, seed=0)
    assert len(s1) == 1400
    assert np.all(s1["y"] == 1.0)
    assert s1["u1"].min() >= 500
    assert s1["u1"].max() <= 3500
    assert s1["u2"].min() >= 0
    assert s1["u2"].max() <= 60
    s2, _ = skf_sim(2, seed=0)
    assert len(s2) == 200
    assert np.all(s2["u1"] == 2000)
    assert np.all(s2["y"] == 1.0)
    u2 = s2["u2"]
    assert np.all(np.diff(u2[:100]) > 0)
    assert np.all(np.diff(u2[100:]) < 0)
    assert u2[99] == 60
    assert u2[-1] == 0
    s3, truth3 = skf_sim(3, seed=0)
    assert_array_equal(s3["u2"], u2)
    noise = s3["y"] - 1.0
    assert np.all(np.abs(noise) <= 0.2)
    assert np.abs(noise).max() > 0.15
    assert_allclose(noise, truth3.noise, rtol=0, atol=1e-15)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sim1_uniform_inputs_all_converge(seed: int) -> None:
    signals, _ = skf_sim(1, seed=seed)
    for kind, tol in SIM1_TOL.items():
        err = _errors(_run(kind, signals), slice(None)).max(axis=1)
        assert err[-1] < tol, kind
        assert err[99] > 10 * err[-1], kind  # it converged, it did not start there


def test_sim2_sweep_kf_and_skf_converge_sskf_does_not() -> None:
    signals, truth = skf_sim(2, seed=0)
    assert list(truth.excited_cells) == EXCITED
    err = {kind: _errors(_run(kind, signals), EXCITED) for kind in ("kf", "skf", "sskf")}
    for kind in ("kf", "skf"):
        assert err[kind][-1].max() < SIM2_TOL, kind
        # The first sweep is not enough; the return sweep completes the convergence.
        assert err[kind][99].max() > 4 * err[kind][-1].max(), kind
    assert err["sskf"][-1].max() > SSKF_FAILS
    assert err["sskf"][-1].max() > 10 * err["kf"][-1].max()
    # Cells the sweep never excites keep θ0 = 0.
    snaps = _run("skf", signals)
    others = [j for j in range(16) if j not in EXCITED]
    assert_array_equal(snaps[-1].table.values.ravel()[others], 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sim3_noisy_sweep_kf_and_skf_filter_the_noise(seed: int) -> None:
    signals, _ = skf_sim(3, seed=seed)
    runs = {kind: _run(kind, signals) for kind in ("kf", "skf", "sskf")}
    err = {kind: _errors(snaps, EXCITED) for kind, snaps in runs.items()}
    for kind in ("kf", "skf"):
        assert err[kind][-1].max() < SIM3_TOL, kind
        assert err[kind][-1].mean() < 0.1, kind
    assert err["sskf"][-1].max() > SSKF_FAILS
    assert err["sskf"][-1].max() > 4 * max(err["kf"][-1].max(), err["skf"][-1].max())

    # KF and SKF variances agree closely at every step (SKF §5.2: small deviations where SKF
    # forgot a cross-covariance), and they are the same as without noise (SKF §5.3).
    var_kf = np.array([s.variance.ravel()[EXCITED] for s in runs["kf"]])
    var_skf = np.array([s.variance.ravel()[EXCITED] for s in runs["skf"]])
    rel = np.abs(var_kf - var_skf) / var_kf
    assert rel.max() < 0.15
    assert np.median(rel) < 0.01
    assert rel.max() > 1e-3  # the SKF approximation is visible: this is not a KF
    noiseless, _ = skf_sim(2, seed=seed)
    var_sim2 = np.array([s.variance.ravel()[EXCITED] for s in _run("kf", noiseless)])
    assert_allclose(var_kf, var_sim2, rtol=1e-12)


SIGMAS = [(1.0, 1.0), (0.5, 2.0), (3.0, 0.3), (0.1, 1.0)]  # (σw, σv)
ETAS = [0.0, 0.1, 0.3, 0.5, 0.77, 0.95, 1.0]


@pytest.mark.parametrize(("sigma_w", "sigma_v"), SIGMAS)
def test_sskf_1d_gain_is_the_riccati_limit(sigma_w: float, sigma_v: float) -> None:
    """SSKF's gain on a 2-breakpoint table equals the limit of the 2-element Riccati
    recursion; read from one SSKF step from θ = 0 with y = 1 (so Δθ = gain)."""
    config = {
        "axes": [{"name": "u1", "breakpoints": [0.0, 1.0]}],
        "output": "y",
        "theta0": 0.0,
        "sigma_w": sigma_w,
        "sigma_v": sigma_v,
    }
    est = get_spec("sskf").build(config)
    r = sigma_v**2 / sigma_w**2
    for eta in ETAS:
        limit = ref.riccati_gain_1d(eta, sigma_w**2, sigma_v**2)
        assert_allclose(
            [ref.sskf_gain(eta, r), ref.sskf_gain(1 - eta, r)], limit, rtol=1e-9, atol=1e-15
        )
        snap = est.fit(Signals([0.0], {"u1": [eta], "y": [1.0]}))
        assert_allclose(snap.table.values, limit, rtol=1e-9, atol=1e-15, err_msg=f"η={eta}")
