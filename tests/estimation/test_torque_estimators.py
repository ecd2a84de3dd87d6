"""Torque estimators of TQ §III/§V: kernels vs slow references, resume, and TQ's orderings."""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation.errors import ConfigError, StateError
from estimation.kernels.torque import R_FLOOR
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
    """TQ (42)–(54) step by step: filters and P, Q, R = K⁻¹ by exact ZOH, Θ̂ by backward Euler
    of Θ̂' = −G(W1 + κW2) with G = Γ (50) or ΓK (54), K = R⁻¹ of the floored R (kernel docs)."""
    scale = {"kg/s": 1.0, "g/s": 1e3, "kg/h": 3.6e3}[c.air_unit]
    n, tl, m = sig["speed_rpm"], sig["load_torque_nm"], scale * sig["air_mass_flow_kg_s"]
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
        W1 = P @ theta - Q  # TQ (46)
        W2 = F @ theta - phi_f[i] * y  # TQ (47)
        K = None if R is None else np.linalg.inv(R + R_FLOOR * np.diag(np.diag(R)))  # TQ (53)
        G = gamma if K is None else gamma @ K
        # backward Euler: θ⁺ = θ − Ts·G·(W1 + κW2)(θ⁺), linear in θ⁺
        A = P + c.kappa * F
        theta = np.linalg.solve(
            np.eye(2) + TS * G @ A, theta - TS * G @ (W1 + c.kappa * W2 - A @ theta)
        )
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
@pytest.mark.parametrize(
    "cfg",
    [
        {"kappa": 0.0},
        {"kappa": 0.1},
        {"kappa": 0.1, "air_unit": "g/s", "gamma": (0.3, 30.0), "theta0": (0.01, 2.0)},
        {"kappa": 0.1, "air_unit": "kg/h", "ell": 3.0, "k": 0.02},
    ],
)
def test_adaptive_kernels_match_slow_reference(name: str, cfg: dict) -> None:
    sig = log()
    if name == "adaptive-tv" and "air_unit" in cfg:
        # scalar Γ: a diagonal one makes (54) diverge on this log (see AdaptiveTvConfig)
        cfg = {**cfg, "K0": (2.0, 1e-4), "gamma": (30.0, 30.0)}
    est = build(name, **cfg)
    got = est.fit(sig).outputs
    want = ref_adaptive(sig, est.config)  # type: ignore[arg-type]
    for key, series in want.items():
        scale = max(1.0, float(np.max(np.abs(series))))
        assert_allclose(got[key], series, rtol=1e-9, atol=1e-9 * scale, err_msg=key)


def test_time_varying_law_survives_a_regressor_without_excitation() -> None:
    """Constant, noise-free N and ṁ_ai: Φ_f excites one direction only, K = (e^{−ℓt}K0 + P)⁻¹
    grows as e^{ℓt} along the other (TQ (53) without PE). The law stays finite and τ̂ = ΦΘ̂
    still fits, since every Θ on the line ΦΘ = τ_e does; no data at all leaves Θ̂ alone."""
    n = 60_000  # 60 s: e^{−ℓt} underflows far below round-off
    t = np.arange(n) * TS
    speed, air = np.full(n, 2000.0), np.full(n, 0.02)
    load = np.full(n, 80.0)  # steady: τ_e = τ_l
    sig = Signals(t, {"speed_rpm": speed, "load_torque_nm": load, "air_mass_flow_kg_s": air})
    for kappa in (0.0, 0.1):
        out = build("adaptive-tv", kappa=kappa).fit(sig).outputs
        assert np.max(np.abs(out["theta2"])) < 1e3  # N·m/(kg/s); round-off alone gave 1e22
        assert np.max(np.abs(out["torque_nm"][-30_000:] - 80.0)) < 1e-3
    zeros = Signals(t, {"speed_rpm": 0 * t, "load_torque_nm": 0 * t, "air_mass_flow_kg_s": 0 * t})
    for name in ("adaptive-const", "adaptive-tv"):
        out = build(name, theta0=(0.01, 3000.0)).fit(zeros).outputs
        assert_allclose(out["theta1"], 0.01, rtol=1e-12)
        assert_allclose(out["theta2"], 3000.0, rtol=1e-12)


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


# --- TQ §VI/§VII orderings (Tables III, IV, VI, VII) on our simulators ---------------------
SEEDS = [0, 1, 2, 3, 4]
SCENARIOS = ["torque-si", "torque-rig"]
ADAPTIVE = [f"{law}/{kappa}" for law in ("adaptive-const", "adaptive-tv") for kappa in (0.0, 0.1)]


@functools.cache
def scores(scenario: str, seed: int) -> dict[str, dict[str, float]]:
    """ISE, MAE, SD over 5–30 s (TQ (60)–(62)) of the estimators with the scenario's default
    configs, as ``mapwise run`` scores them; the adaptive laws with κ = 0 and 0.1."""
    sc = get_scenario(scenario)
    data = sc.build(seed=seed)
    truth = data.scored_series["torque_nm"]
    variants = {name: (name, {}) for name in ("uio", "smo", "dirty")}
    for key in ADAPTIVE:
        law, kappa = key.split("/")
        variants[key] = (law, {"kappa": float(kappa)})
    out = {}
    for key, (name, extra) in variants.items():
        est = build(name, **(sc.default_config(name) | extra))
        estimate = est.fit(data.signals).outputs["torque_nm"]
        out[key] = torque_metrics(data.signals.time, truth - estimate, window_s=(5, 30))
    return out


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_uio_beats_sliding_mode_and_dirty_differentiation(scenario: str, seed: int) -> None:
    """TQ Tables III (§VI) and VI (§VII): the UIO has the lowest ISE and SD of the three."""
    m = scores(scenario, seed)
    for other in ("smo", "dirty"):
        assert m["uio"]["ise"] < m[other]["ise"], (other, m)
        assert m["uio"]["sd"] < m[other]["sd"], (other, m)


NO_PE_ON_SI = (
    "TQ Table IV: (54) with κ = 0.1 should have the lowest ISE and SD of the four adaptive "
    "variants. On torque-si, seeds 0–4, it has ISE 442–500 N²·m²·s and SD 4.20–4.47 N·m "
    "against 123–125 and 2.22–2.24 for (50) with κ = 0 (≈ 4× the ISE). Cause: no persistent "
    "excitation (TQ Lemma 8). At constant speed N and ṁ_ai are proportional (λ_min/λ_max of the "
    "diagonally scaled P ≈ 5e-8 from 15 to 30 s), so K ≈ P⁻¹ lets the speed noise, which enters "
    "both Φ_f and y, steer Θ̂ along the unexcited direction (θ̂ ≈ (−0.3…−1.7 N·m/rpm, "
    "3e4…2e5 N·m/(kg/s)) against the true (−0.009, 5e3)); ΦΘ̂ fits at the operating point but "
    "spikes at the speed steps (MAE 44–194 N·m vs 20). (50) with ṁ_ai in kg/s never moves θ2 "
    "(rate Γ2·ṁ_ai²/ℓ ≈ 3e-3 /s) and so cannot drift."
)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize(
    "scenario",
    [
        pytest.param("torque-si", marks=pytest.mark.xfail(strict=True, reason=NO_PE_ON_SI)),
        "torque-rig",
    ],
)
def test_time_varying_gain_with_kappa_is_best_adaptive_variant(scenario: str, seed: int) -> None:
    """The issue's target from TQ Tables IV/VII: (54) with κ = 0.1 has the lowest ISE and SD.
    (TQ Table VII itself ranks (50) with κ = 0.1 first on the rig; see the next test.)"""
    m = scores(scenario, seed)
    best = "adaptive-tv/0.1"
    for key in ADAPTIVE:
        if key != best:
            assert m[best]["ise"] < m[key]["ise"], (key, m)
            assert m[best]["sd"] < m[key]["sd"], (key, m)


@pytest.mark.xfail(
    strict=True,
    reason="TQ Table VII ranks (50) with κ = 0.1 first on the rig (ISE 3.03e5 vs 3.56e5 for "
    "(54) κ = 0.1). On torque-rig, seeds 0–4, (50) κ = 0.1 has ISE 1596–1615, SD 7.99–8.03 "
    "against 306–316, 3.46–3.51 for (54) κ = 0.1. Cause: Θ moves fast on our diesel "
    "(θ2 = τ_i/ṁ_ai jumps at each fuel-demand step while ṁ_ai follows the 0.4 s turbo lag) "
    "and (50) with ṁ_ai in kg/s adapts θ1 alone; with air_unit='kg/h', which balances TQ's "
    "Γ = diag(0.1, 100), its ISE drops to ≈ 500, still above (54).",
)
@pytest.mark.parametrize("seed", SEEDS)
def test_constant_gain_with_kappa_is_best_on_the_rig(seed: int) -> None:
    m = scores("torque-rig", seed)
    for key in ADAPTIVE:
        if key != "adaptive-const/0.1":
            assert m["adaptive-const/0.1"]["ise"] < m[key]["ise"], (key, m)
            assert m["adaptive-const/0.1"]["sd"] < m[key]["sd"], (key, m)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("law", ["adaptive-const", "adaptive-tv"])
def test_kappa_reduces_the_peak_error(law: str, scenario: str, seed: int) -> None:
    """TQ §VI: W2 "reduces the peak errors at the transient points" (Tables IV, VII: MAE
    19.2 → 14.8 and 19.7 → 12.7 in simulation, 15.4 → 9.4 and 17.3 → 9.7 on the rig)."""
    m = scores(scenario, seed)
    assert m[f"{law}/0.1"]["mae"] < m[f"{law}/0.0"]["mae"], m


W2_NOISE_ON_SI = (
    "TQ Table IV: κ = 0.1 also lowers ISE and SD of (50) (1.55e5 → 1.33e5, 2.62 → 2.43). On "
    "torque-si, seeds 0–4, it raises them slightly: ISE 122.7–125.0 → 125.0–127.9, SD "
    "2.215–2.236 → 2.236–2.262. W2 feeds the instantaneous UIO signal y, whose speed noise "
    "J/k·w1 ≈ 2.4 N·m SD sits at TQ Table III's level, into θ̂1, while Θ of our mean value "
    "plant varies slowly (no fast combustion dynamics, ṁ_ai noise-free), so the smaller peaks "
    "at the steps (MAE 20.5 → 14.5, TQ 19.2 → 14.8) do not pay for it over 25 s."
)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize(
    ("law", "scenario"),
    [
        pytest.param(
            "adaptive-const",
            "torque-si",
            marks=pytest.mark.xfail(strict=True, reason=W2_NOISE_ON_SI),
        ),
        ("adaptive-const", "torque-rig"),
        ("adaptive-tv", "torque-si"),
        ("adaptive-tv", "torque-rig"),
    ],
)
def test_kappa_reduces_ise_and_sd(law: str, scenario: str, seed: int) -> None:
    """TQ Tables IV and VII: ISE and SD fall when κ goes from 0 to 0.1, for both laws."""
    m = scores(scenario, seed)
    for metric in ("ise", "sd"):
        assert m[f"{law}/0.1"][metric] < m[f"{law}/0.0"][metric], (metric, m)


def test_paper_diagonal_gain_destabilises_the_time_varying_law() -> None:
    """Why AdaptiveTvConfig's Γ is scalar: TQ's Γ = diag(0.1, 100) (stated for (50)) breaks
    Theorem 4's Lyapunov argument, and on torque-si (54) with κ = 0.1 diverges with it."""
    sc = get_scenario("torque-si")
    data = sc.build(seed=0)
    cfg = sc.default_config("adaptive-tv") | {"kappa": 0.1}
    assert AdaptiveTvConfig(**cfg).gamma[0] == AdaptiveTvConfig(**cfg).gamma[1]
    with np.errstate(all="ignore"):
        paper = build("adaptive-tv", **cfg, gamma=(0.1, 100.0)).fit(data.signals).outputs
        ours = build("adaptive-tv", **cfg).fit(data.signals).outputs
    assert not np.all(np.abs(paper["theta1"]) < 1e6)  # non-finite or runaway
    assert np.all(np.abs(ours["theta1"]) < 1e2)
