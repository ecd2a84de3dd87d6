"""Torque estimators of TQ §III/§V: kernels vs slow references, resume, and TQ's orderings."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation.errors import ConfigError, StateError
from estimation.metrics import torque_metrics
from estimation.scenarios import get_scenario
from estimation.signals import Signals
from estimation.torque import (
    TORQUE_SPECS,
    AdaptiveConstConfig,
    AdaptiveTvConfig,
    DirtyConfig,
    SmoConfig,
    TorqueEstimator,
    TorqueState,
    UioConfig,
    initial_state,
    run_chunk,
)

TS = 1e-3
NAMES = ["uio", "smo", "dirty", "adaptive-const", "adaptive-tv"]
CONFIG = {
    "uio": UioConfig,
    "smo": SmoConfig,
    "dirty": DirtyConfig,
    "adaptive-const": AdaptiveConstConfig,
    "adaptive-tv": AdaptiveTvConfig,
}


def log(n: int = 800, seed: int = 0) -> Signals:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * TS
    speed = 2200 + 300 * np.sin(2 * np.pi * 0.7 * t) + rng.normal(0, 4.5, n)
    load = 90 + 20 * np.sin(2 * np.pi * 1.3 * t) + rng.normal(0, 4.5, n)
    air = 0.02 + 0.005 * np.sin(2 * np.pi * 1.1 * t + 0.4) + rng.normal(0, 1e-4, n)
    channels = {"speed_rpm": speed, "load_torque_nm": load, "air_mass_flow_kg_s": air}
    return Signals(t, channels, {"speed_rpm": "rpm"})


# --- slow references: plain loops, direct discretisation ---------------------------------
def ref_filter(u: np.ndarray, k: float) -> np.ndarray:
    """``k ẋ + x = u`` under a ZOH of u, x(0) = 0: value at t_i from inputs before i."""
    a = math.exp(-TS / k)
    x, out = 0.0, []
    for v in u:
        out.append(x)
        x = a * x + (1 - a) * v
    return np.array(out)


def ref_uio(n: np.ndarray, tl: np.ndarray, J: float, k: float) -> np.ndarray:
    return J * (n - ref_filter(n, k)) / k + ref_filter(tl, k)


def ref_dirty(n: np.ndarray, tl: np.ndarray, J: float, k: float) -> np.ndarray:
    return J * n / k - J / k * ref_filter(n, k) + tl


def ref_smo(n: np.ndarray, tl: np.ndarray, J: float, k: float, lam: float) -> np.ndarray:
    n_hat, v = 0.0, []
    for i in range(n.size):
        v.append(lam * np.sign(n[i] - n_hat))
        n_hat += TS / J * (-tl[i] + v[-1])
    return ref_filter(np.array(v), k)


def ref_adaptive(sig: Signals, c: AdaptiveConstConfig | AdaptiveTvConfig) -> dict[str, list]:
    n, tl, m = sig["speed_rpm"], sig["load_torque_nm"], sig["air_mass_flow_kg_s"]
    J, k, ell = c.J_nm_s_per_rpm, c.k, c.ell
    n_f, t_lf = ref_filter(n, k), ref_filter(tl, k)
    phi_f = np.column_stack([ref_filter(n, k), ref_filter(m, k)])
    b = math.exp(-ell * TS)
    P, Q = np.zeros((2, 2)), np.zeros(2)
    R = np.diag(c.K0) if isinstance(c, AdaptiveTvConfig) else None
    gamma = np.diag(c.gamma)
    theta = np.array(c.theta0, dtype=float)
    out: dict[str, list] = {"torque_nm": [], "theta1": [], "theta2": [], "pe_lambda_min": []}
    for i in range(n.size):
        y = J * (n[i] - n_f[i]) / k + t_lf[i]
        out["torque_nm"].append(np.array([n[i], m[i]]) @ theta)
        out["theta1"].append(theta[0])
        out["theta2"].append(theta[1])
        out["pe_lambda_min"].append(np.linalg.eigvalsh(P)[0])
        F = np.outer(phi_f[i], phi_f[i])
        A = P + c.kappa * F
        rhs = Q + c.kappa * phi_f[i] * y
        G = gamma if R is None else gamma @ np.linalg.inv(R)
        theta = np.linalg.solve(np.eye(2) + TS * G @ A, theta + TS * G @ rhs)
        P = b * P + (1 - b) / ell * F
        Q = b * Q + (1 - b) / ell * phi_f[i] * y
        if R is not None:
            R = b * R + (1 - b) / ell * F
    return out


def build(name: str, **cfg: object) -> TorqueEstimator:
    return TorqueEstimator(name, CONFIG[name](**cfg))


@pytest.mark.parametrize("name", ["uio", "smo", "dirty"])
def test_observer_kernels_match_slow_reference(name: str) -> None:
    sig = log()
    est = build(name)
    got = est.fit(sig).outputs["torque_nm"]
    c = est.config
    n, tl = sig["speed_rpm"], sig["load_torque_nm"]
    if name == "uio":
        want = ref_uio(n, tl, c.J_nm_s_per_rpm, c.k)
    elif name == "dirty":
        want = ref_dirty(n, tl, c.J_nm_s_per_rpm, c.k)
    else:
        assert isinstance(c, SmoConfig)
        want = ref_smo(n, tl, c.J_nm_s_per_rpm, c.k, c.lambda1)
    assert_allclose(got, want, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", ["adaptive-const", "adaptive-tv"])
@pytest.mark.parametrize("kappa", [0.0, 0.1])
def test_adaptive_kernels_match_slow_reference(name: str, kappa: float) -> None:
    sig = log()
    est = build(name, kappa=kappa)
    got = est.fit(sig).outputs
    want = ref_adaptive(sig, est.config)  # type: ignore[arg-type]
    for key, series in want.items():
        scale = max(1.0, float(np.max(np.abs(series))))
        assert_allclose(got[key], series, rtol=1e-9, atol=1e-9 * scale, err_msg=key)


@pytest.mark.parametrize("name", NAMES)
def test_resume_from_any_snapshot_is_bit_identical(name: str) -> None:
    sig = log(n=700, seed=1)
    est = build(name)
    whole = est.fit(sig)
    snaps = list(est.run(sig, every=97))
    assert [s.chunk_start for s in snaps] == list(range(0, 700, 97))
    joined = np.concatenate([s.outputs["torque_nm"] for s in snaps])
    assert_array_equal(joined, whole.outputs["torque_nm"])
    for s in snaps[:-1]:
        state = TorqueState.from_dict(json.loads(json.dumps(s.state.to_dict())))
        rest = list(est.run(sig, state=state))
        for key, full in whole.outputs.items():
            tail = np.concatenate([r.outputs[key] for r in rest])
            assert_array_equal(tail, full[s.sample :], err_msg=key)
        assert_array_equal(rest[-1].state.x, whole.state.x)
    last = snaps[-1]
    assert last.done
    assert last.table is None
    assert last.rejected == {}
    assert_array_equal(last.status, np.zeros(last.sample - last.chunk_start, np.int8))


def test_class_and_procedure_forms_agree() -> None:
    sig = log()
    est = build("adaptive-tv")
    state = initial_state("adaptive-tv", est.config)
    inputs = {
        "speed_rpm": sig["speed_rpm"],
        "load_nm": sig["load_torque_nm"],
        "air_kg_s": sig["air_mass_flow_kg_s"],
    }
    state, out = run_chunk(state, est.config, inputs, sample_period_s=sig.sample_period())
    snap = est.fit(sig)
    assert state.step == snap.sample == len(sig)
    for key in out:
        assert_array_equal(out[key], snap.outputs[key])


def test_specs_errors_and_state_checks() -> None:
    specs = {s.name: s for s in TORQUE_SPECS}
    assert list(specs) == NAMES
    assert all(not s.produces_map and "Na, Chen" in s.paper for s in specs.values())
    est = specs["adaptive-tv"].build({"kappa": 0.0})
    assert est.required_signals() == ["speed_rpm", "load_torque_nm", "air_mass_flow_kg_s"]
    with pytest.raises(ConfigError, match="lambda2: Extra inputs"):
        specs["smo"].build({"lambda2": 1.0})
    sig = log(n=50)
    uio_state = build("uio").fit(sig).state
    with pytest.raises(StateError, match="'uio' estimator cannot resume 'dirty'"):
        next(build("dirty").run(sig, state=uio_state))
    with pytest.raises(ConfigError, match="rejects 1 of them"):
        next(build("uio").run(sig, accept=np.arange(50) != 3))
    with pytest.raises(ConfigError, match="every must be >= 1"):
        next(build("uio").run(sig, every=0))


# --- TQ §VI orderings (Tables III and IV) on our simulator -----------------------------
def scores(scenario: str, seed: int) -> dict[str, dict[str, float]]:
    data = get_scenario(scenario).build(seed=seed)
    J = float(data.truth["J_nm_s_per_rpm"])
    truth = np.asarray(data.truth["torque_nm"])
    variants = {
        "uio": build("uio", J_nm_s_per_rpm=J),
        "smo": build("smo", J_nm_s_per_rpm=J),
        "dirty": build("dirty", J_nm_s_per_rpm=J),
    }
    for name in ("adaptive-const", "adaptive-tv"):
        for kappa in (0.0, 0.1):
            variants[f"{name}/{kappa}"] = build(name, J_nm_s_per_rpm=J, kappa=kappa)
    out = {}
    for key, est in variants.items():
        estimate = est.fit(data.signals).outputs["torque_nm"]
        out[key] = torque_metrics(data.signals.time, truth - estimate, window_s=(5, 30))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_uio_beats_sliding_mode_and_dirty_differentiation_on_si(seed: int) -> None:
    m = scores("torque-si", seed)
    for other in ("smo", "dirty"):
        assert m["uio"]["ise"] < m[other]["ise"], (other, m)
        assert m["uio"]["sd"] < m[other]["sd"], (other, m)


@pytest.mark.xfail(
    strict=True,
    reason="TQ Table IV ordering does not hold on our SI plant: N and ṁ_ai are nearly "
    "collinear, Θ is poorly excited, and the constant-gain law with κ = 0 has the lowest "
    "ISE/SD (seed 0: ISE 1498 vs 2999 for (54) with κ = 0.1)",
)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_time_varying_gain_with_kappa_is_best_adaptive_variant(seed: int) -> None:
    m = scores("torque-si", seed)
    best = "adaptive-tv/0.1"
    for key in ("adaptive-const/0.0", "adaptive-const/0.1", "adaptive-tv/0.0"):
        assert m[best]["ise"] < m[key]["ise"], (key, m)
        assert m[best]["sd"] < m[key]["sd"], (key, m)
