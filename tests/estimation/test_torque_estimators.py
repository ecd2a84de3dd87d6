"""Torque estimators of TQ §III/§V: kernels vs slow references, resume, and TQ's orderings."""

from __future__ import annotations

import functools
import json
import math

import numba
import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from numpy.testing import assert_allclose, assert_array_equal

from estimation.errors import ConfigError, StateError
from estimation.kernels.torque import R_FLOOR, SUBSTEPS
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


RADAU_A = np.array([[5 / 12, -1 / 12], [3 / 4, 1 / 4]])  # Radau IIA, 2 stages (Butcher)
RADAU_B = np.array([3 / 4, 1 / 4])
RADAU_C = np.array([1 / 3, 1.0])


def ref_adaptive(sig: Signals, c: AdaptiveConstConfig | AdaptiveTvConfig) -> dict[str, list]:
    """TQ (42)–(54) under a ZOH of N, τ_l, ṁ_ai, step by step with matrices.

    Filters, P, Q and R = K⁻¹ (TQ (53)) exactly by one matrix exponential per sample (Van
    Loan): the filter states ``z`` and ``1`` obey ``ż = Lz``, so ``Z = zzᵀ`` obeys
    ``Ż = LZ + ZLᵀ``, and ``Ṗ = −ℓP + EZEᵀ``, ``Q̇ = −ℓQ + EZc_y`` are linear in ``Z``.
    Θ̂' = −G(AΘ̂ − c) with G = Γ (50) or Γ·inv(R̃) (54) by the Radau IIA tableau in its
    textbook form, SUBSTEPS steps per sample (kernel docs)."""
    scale = {"kg/s": 1.0, "g/s": 1e3, "kg/h": 3.6e3}[c.air_unit]
    speed, load = sig["speed_rpm"], sig["load_torque_nm"]
    air = scale * sig["air_mass_flow_kg_s"]
    J, k, ell, kappa = c.J_nm_s_per_rpm, c.k, c.ell, c.kappa
    tv = isinstance(c, AdaptiveTvConfig)
    gamma = np.diag(c.gamma)
    hs = TS / SUBSTEPS
    z = np.zeros(4)  # N_f, τ_lf, Φ_f1, Φ_f2
    P, Q = np.zeros((2, 2)), np.zeros(2)
    R = np.diag(c.K0) if isinstance(c, AdaptiveTvConfig) else np.eye(2)
    theta = np.array(c.theta0, dtype=float)
    E, I5 = np.eye(5)[2:4], np.eye(5)
    out: dict[str, list] = {"torque_nm": [], "theta1": [], "theta2": [], "pe_lambda_min": []}
    for N, tl, m in zip(speed, load, air, strict=True):
        out["torque_nm"].append(N * theta[0] + m * theta[1])
        out["theta1"].append(theta[0])
        out["theta2"].append(theta[1])
        out["pe_lambda_min"].append(np.linalg.eigvalsh(P)[0])
        L = np.zeros((5, 5))  # d/dt [N_f, τ_lf, Φ_f1, Φ_f2, 1]: TQ (9), (42)
        L[:4, :4] = -np.eye(4) / k
        L[:4, 4] = np.array([N, tl, N, m]) / k
        c_y = np.array([-J / k, 1.0, 0.0, 0.0, J * N / k])  # y = J(N − N_f)/k + τ_lf
        gen = np.zeros((35, 35))  # [vec Z, vec P, Q, vec R]
        gen[:25, :25] = np.kron(L, I5) + np.kron(I5, L)
        gen[25:29, :25] = np.kron(E, E)
        gen[29:31, :25] = np.kron(E, c_y[None, :])
        gen[31:35, :25] = np.kron(E, E)
        gen[25:, 25:] = -ell * np.eye(10)
        props = [scipy.linalg.expm(gen * node * hs) for node in RADAU_C]
        for _ in range(SUBSTEPS):
            ze = np.append(z, 1.0)
            x0 = np.concatenate([np.outer(ze, ze).ravel(), P.ravel(), Q, R.ravel()])
            jac, force = [], []
            for prop in props:
                x = prop @ x0
                zr = x[:25].reshape(5, 5)[:, 4]
                Pr, Qr, Rr = x[25:29].reshape(2, 2), x[29:31], x[31:35].reshape(2, 2)
                phi, y = zr[2:4], c_y @ zr
                A = Pr + kappa * np.outer(phi, phi)  # W1 + κW2 = AΘ̂ − c, TQ (46)–(47)
                cc = Qr + kappa * phi * y
                G = gamma @ np.linalg.inv(Rr + R_FLOOR * np.diag(np.diag(Rr))) if tv else gamma
                jac.append(-G @ A)
                force.append(G @ cc)
            # stages Y_j = Θ̂ + hs·Σ_l a_jl·f_l(Y_l), f_l(θ) = jac_l·θ + force_l
            big = np.eye(4) - hs * np.block(
                [[RADAU_A[j, i] * jac[i] for i in range(2)] for j in range(2)]
            )
            rhs = np.concatenate([theta + hs * (RADAU_A[j] @ np.array(force)) for j in range(2)])
            Y = np.linalg.solve(big, rhs).reshape(2, 2)
            theta = theta + hs * sum(RADAU_B[j] * (jac[j] @ Y[j] + force[j]) for j in range(2))
            z = zr[:4]
            P, Q, R = (Pr + Pr.T) / 2, Qr, (Rr + Rr.T) / 2
    return out


def start_of_step_adaptive(sig: Signals, c: AdaptiveConstConfig | AdaptiveTvConfig) -> dict:
    """The kernel's scheme before the ZOH-exact forcing, kept to show the continuous-law test
    catches it: P, Q, R forced by Φ_f, y held at their values at t_i (they move ~10 % within
    a step at Ts/k = 0.1), Θ̂ by backward Euler with everything at t_i."""
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
    torque = []
    for i in range(n.size):
        y = J * (n[i] - n_f[i]) / k + t_lf[i]
        torque.append(np.array([n[i], m[i]]) @ theta)
        F = np.outer(phi_f[i], phi_f[i])
        K = None if R is None else np.linalg.inv(R + R_FLOOR * np.diag(np.diag(R)))
        G = gamma if K is None else gamma @ K
        A = P + c.kappa * F
        theta = np.linalg.solve(
            np.eye(2) + TS * G @ A, theta + TS * G @ (Q + c.kappa * phi_f[i] * y)
        )
        P = b * P + (1 - b) / ell * F
        Q = b * Q + (1 - b) / ell * phi_f[i] * y
        if R is not None:
            R = b * R + (1 - b) / ell * F
    return {"torque_nm": np.array(torque)}


@numba.njit(cache=True)
def _rk4_continuous(speed, load, air, J, k, ell, g1, g2, kappa, tv, K0, theta0, substeps):
    """RK4 with ``substeps`` steps per sample of the continuous TQ (9), (42), (45), (50)/(52),
    (54) on held inputs, K by its Riccati equation (no floor). Per sample: UIO, dirty
    differentiation and adaptive-law torque at t_i."""
    x = np.zeros(14)  # N_f, τ_lf, Φ_f1, Φ_f2, P11, P12, P22, Q1, Q2, K11, K12, K22, θ1, θ2
    x[9], x[11], x[12], x[13] = 1.0 / K0[0], 1.0 / K0[1], theta0[0], theta0[1]
    out = np.empty((speed.size, 3))
    h = TS / substeps
    for i in range(speed.size):
        N, tl, m = speed[i], load[i], air[i]
        out[i, 0] = J * (N - x[0]) / k + x[1]
        out[i, 1] = J * (N - x[0]) / k + tl
        out[i, 2] = N * x[12] + m * x[13]
        for _ in range(substeps):
            k1 = _tq_rhs(x, N, tl, m, J, k, ell, g1, g2, kappa, tv)
            k2 = _tq_rhs(x + 0.5 * h * k1, N, tl, m, J, k, ell, g1, g2, kappa, tv)
            k3 = _tq_rhs(x + 0.5 * h * k2, N, tl, m, J, k, ell, g1, g2, kappa, tv)
            k4 = _tq_rhs(x + h * k3, N, tl, m, J, k, ell, g1, g2, kappa, tv)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


@numba.njit(cache=True)
def _tq_rhs(x, N, tl, m, J, k, ell, g1, g2, kappa, tv):
    nf, tlf, f1, f2, p11, p12, p22, q1, q2, k11, k12, k22, t1, t2 = x
    y = J * (N - nf) / k + tlf
    kf1, kf2 = k11 * f1 + k12 * f2, k12 * f1 + k22 * f2
    e = f1 * t1 + f2 * t2 - y
    w1 = p11 * t1 + p12 * t2 - q1 + kappa * f1 * e  # W1 + κW2, TQ (46)–(47)
    w2 = p12 * t1 + p22 * t2 - q2 + kappa * f2 * e
    d = np.empty(14)
    d[0], d[1], d[2], d[3] = (N - nf) / k, (tl - tlf) / k, (N - f1) / k, (m - f2) / k
    d[4], d[5], d[6] = -ell * p11 + f1 * f1, -ell * p12 + f1 * f2, -ell * p22 + f2 * f2
    d[7], d[8] = -ell * q1 + f1 * y, -ell * q2 + f2 * y
    d[9], d[10], d[11] = ell * k11 - kf1 * kf1, ell * k12 - kf1 * kf2, ell * k22 - kf2 * kf2
    if tv:
        d[12], d[13] = -g1 * (k11 * w1 + k12 * w2), -g2 * (k12 * w1 + k22 * w2)
    else:
        d[12], d[13] = -g1 * w1, -g2 * w2
    return d


def continuous(sig: Signals, c: UioConfig | AdaptiveConstConfig | AdaptiveTvConfig) -> np.ndarray:
    """``(n, 3)``: UIO, dirty differentiation, adaptive law on ``sig`` by fine-step RK4."""
    ad = c if isinstance(c, AdaptiveConstConfig | AdaptiveTvConfig) else AdaptiveConstConfig()
    scale = {"kg/s": 1.0, "g/s": 1e3, "kg/h": 3.6e3}[ad.air_unit]
    K0 = np.array(ad.K0 if isinstance(ad, AdaptiveTvConfig) else (1.0, 1.0))
    return _rk4_continuous(
        sig["speed_rpm"],
        sig["load_torque_nm"],
        scale * sig["air_mass_flow_kg_s"],
        c.J_nm_s_per_rpm,
        c.k,
        ad.ell,
        ad.gamma[0],
        ad.gamma[1],
        ad.kappa,
        isinstance(ad, AdaptiveTvConfig),
        K0,
        np.array(ad.theta0),
        100,  # 10 µs: h·λ ≈ 1 for the stiffest mode Γ1(P11 + κΦ_f1²) ≈ 10⁵ s⁻¹ (converged)
    )


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


@pytest.mark.slow
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


@pytest.mark.parametrize("name", ["uio", "dirty"])
def test_observer_kernels_are_the_continuous_estimators_at_the_samples(name: str) -> None:
    """UIO and dirty differentiation are algebraic in exact ZOH filter states: the kernels
    equal the continuous TQ (9)/(14), (23)–(24) sampled at t_i."""
    sig = log()
    est = build(name)
    got = est.fit(sig).outputs["torque_nm"]
    want = continuous(sig, est.config)[:, 0 if name == "uio" else 1]  # type: ignore[arg-type]
    assert_allclose(got, want, rtol=0, atol=1e-9 * float(np.max(np.abs(want))))


@pytest.mark.parametrize("kappa", [0.0, 0.1])
@pytest.mark.parametrize("name", ["adaptive-const", "adaptive-tv"])
def test_adaptive_kernels_follow_the_continuous_law_under_zoh(name: str, kappa: float) -> None:
    """The kernel against RK4 of the continuous equations (K by its Riccati equation, TQ (52))
    at 100 steps per sample. After the 0.1 s start-up (Θ̂(0) = 0 overshoots to ~10⁴ N·m) within
    1e-3 N·m (measured ≤ 2e-4; τ̂ ≈ 70–190 N·m); the former start-of-step scheme misses by
    0.5–3.2 N·m and fails it. In the start-up, where Θ̂ moves by up to 10³ N·m per sample,
    within 0.2 % of max |τ̂| (measured ≤ 0.13 %: Radau IIA's O(h³) on SUBSTEPS steps)."""
    sig = log()
    fast = {"gamma": (100.0, 100.0)} if name == "adaptive-tv" else {}  # the 0.1 s start-up
    est = build(name, kappa=kappa, **fast)
    exact = continuous(sig, est.config)[:, 2]  # type: ignore[arg-type]
    got = est.fit(sig).outputs["torque_nm"]
    old = start_of_step_adaptive(sig, est.config)["torque_nm"]  # type: ignore[arg-type]
    after = slice(100, None)
    assert_allclose(got[after], exact[after], rtol=0, atol=1e-3)
    assert np.max(np.abs(old[after] - exact[after])) > 0.3
    assert np.max(np.abs(got - exact)) < 2e-3 * np.max(np.abs(exact))


def test_noise_alone_leaves_filtered_speed_and_y_uncorrelated() -> None:
    """Zero-mean noise on N and τ_l (variance 20, as the scenarios): in continuous time
    E[N_f·Ṅ_f] = 0, so P and Q must see no correlation between Φ_f1 and y = J(N − N_f)/k +
    τ_lf. The kernel's mean Q1 / mean P11 (what P⁻¹Q of TQ (45) fits to θ1) is < 5 % of J/k
    (measured < 1 % over 100 s); Φ_f1, y held at t_i, as the former kernel integrated them,
    give −J/k: E[N_f(t_i)·(N_i − N_f(t_i))] = −var(N_f), a correlation of −0.2."""
    n = 100_000
    rng = np.random.default_rng(7)
    t = np.arange(n) * TS
    speed, load = rng.normal(0, math.sqrt(20), n), rng.normal(0, math.sqrt(20), n)
    sig = Signals(t, {"speed_rpm": speed, "load_torque_nm": load, "air_mass_flow_kg_s": 0 * t})
    est = build("adaptive-const", kappa=0.0)
    states = [s.state for s in est.run(sig, every=50)][20:]  # after 1 s (1/ℓ = 0.1 s)
    J, k = est.config.J_nm_s_per_rpm, est.config.k
    fitted = np.mean([s.Q[0] for s in states]) / np.mean([s.P[0, 0] for s in states])
    assert abs(fitted) < 0.05 * J / k
    n_f = ref_filter(speed, k)
    y = J * (speed - n_f) / k + ref_filter(load, k)
    held = np.mean(n_f * y) / np.mean(n_f * n_f)
    assert held == pytest.approx(-J / k, rel=0.1)
    assert np.corrcoef(n_f, y)[0, 1] == pytest.approx(-0.2, abs=0.02)


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
# Claims are asserted on the held-out seeds 100–109 under mismatch="nominal" (the estimators'
# J drawn ±10 % around the plant's; docs/fidelity.md): nothing was tuned on them. The plants'
# inertia, firing ripple and rig sensor noise come from physics and data-sheet values, not
# from TQ's tables (estimation/plants/torque_params.py). Where a table's ordering does not
# hold, the test asserts the ordering that does, with the figures.
SEEDS = list(range(100, 110))
SCENARIOS = ["torque-si", "torque-rig"]
ADAPTIVE = [f"{law}/{kappa}" for law in ("adaptive-const", "adaptive-tv") for kappa in (0.0, 0.1)]


@functools.cache
def errors(scenario: str, seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Time [s] and τ̃ = τ_e − τ̂_e [N·m] of the estimators with the scenario's default
    configs, as ``mapwise run`` runs them; the adaptive laws with κ = 0 and 0.1."""
    sc = get_scenario(scenario)
    data = sc.build(seed=seed, mismatch="nominal")
    truth = data.scored_series["torque_nm"]
    variants = {name: (name, {}) for name in ("uio", "smo", "dirty")}
    for key in ADAPTIVE:
        law, kappa = key.split("/")
        variants[key] = (law, {"kappa": float(kappa)})
    out = {}
    for key, (name, extra) in variants.items():
        est = build(name, **(sc.default_config(name, data=data) | extra))
        out[key] = truth - est.fit(data.signals).outputs["torque_nm"]
    return data.signals.time, out


@functools.cache
def scores(scenario: str, seed: int) -> dict[str, dict[str, float]]:
    """ISE, MAE, SD over 5–30 s (TQ (60)–(62)) of :func:`errors`, as ``mapwise run`` scores
    them."""
    t, err = errors(scenario, seed)
    return {key: torque_metrics(t, e, window_s=(5, 30)) for key, e in err.items()}


def seed_mean(scenario: str, key: str, metric: str) -> float:
    return float(np.mean([scores(scenario, seed)[key][metric] for seed in SEEDS]))


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_uio_beats_sliding_mode(scenario: str, seed: int) -> None:
    """TQ Tables III (§VI) and VI (§VII): the UIO has lower ISE and SD than the sliding-mode
    estimator. Nominal, seeds 100–109: torque-si ISE 1146–1579 against 2521–2720, torque-rig
    3342–4588 against 12653–13199."""
    m = scores(scenario, seed)
    assert m["uio"]["ise"] < m["smo"]["ise"], m
    assert m["uio"]["sd"] < m["smo"]["sd"], m


@pytest.mark.parametrize("seed", SEEDS)
def test_uio_beats_dirty_differentiation_on_si(seed: int) -> None:
    """TQ Table III: the UIO has lower ISE and SD than dirty differentiation, which passes the
    §VI load noise N(0, 20) unfiltered (TQ (37)). Nominal, seeds 100–109: ISE 1146–1579
    against 1627–2047, SD 6.77–7.95 against 8.07–9.05."""
    m = scores("torque-si", seed)
    assert m["uio"]["ise"] < m["dirty"]["ise"], m
    assert m["uio"]["sd"] < m["dirty"]["sd"], m


@pytest.mark.parametrize("seed", SEEDS)
def test_dirty_differentiation_edges_the_uio_on_the_rig(seed: int) -> None:
    """A miss of TQ Table VI (UIO lowest ISE and SD on the rig): on torque-rig dirty
    differentiation is marginally better on every held-out seed (nominal, seeds 100–109: UIO
    ISE 0.6–1.7 % and SD 0.3–0.8 % above dirty's, ISE 3342–4588 against 3287–4556).

    Cause: the two differ only in τ_l against its filtered τ_lf (TQ (14), (24)). The rig's
    0.1 %-class load measurement has σ = 0.5 N·m, so filtering it gains little, while τ_lf
    lags the dyno's fast load swings by k = 0.01 s. Evidence on seed 100 (the rig plant with
    the nominal draw's J, docs/fidelity.md#held-out): without noise dirty differentiation wins
    too (ISE 553 against 607), and with §VI's load noise σ = √20 the UIO wins (3574 against
    3984)."""
    m = scores("torque-rig", seed)
    assert 1.0 < m["uio"]["ise"] / m["dirty"]["ise"] < 1.03, m
    assert 1.0 < m["uio"]["sd"] / m["dirty"]["sd"] < 1.015, m


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_time_varying_gain_with_kappa_is_best_adaptive_variant(scenario: str, seed: int) -> None:
    """TQ Table IV (§VI) under the frozen Γ = 10·I of (54) (chosen on tuning seeds 0–4,
    app/reproduce/sensitivity.py, docs/estimators.md#dev-tq-gamma-54): (54) with κ = 0.1 has
    the lowest ISE and SD of the four adaptive variants. Nominal, seeds 100–109: torque-si ISE
    149–199 against ≥ 172 ((54) κ = 0, which drifts to 2534 on seed 103) and 213–432 for (50),
    SD 2.45–2.82 against ≥ 2.62; torque-rig ISE 1413–1532 against ≥ 2311, SD 7.47–7.77
    against ≥ 9.61. (TQ Table VII itself ranks (50) with κ = 0.1 first on the rig; below.)"""
    m = scores(scenario, seed)
    best = "adaptive-tv/0.1"
    for key in ADAPTIVE:
        if key != best:
            assert m[best]["ise"] < m[key]["ise"], (key, m)
            assert m[best]["sd"] < m[key]["sd"], (key, m)


@pytest.mark.parametrize("seed", SEEDS)
def test_constant_gain_with_kappa_is_not_first_on_the_rig(seed: int) -> None:
    """TQ Table VII ranks (50) with κ = 0.1 first on the rig; here (54) with κ = 0.1 beats it
    on ISE and SD on every held-out seed (docs/estimators.md#dev-tq-rig-ranking; nominal,
    seeds 100–109: ISE 2311–2938 against 1413–1532, SD 9.61–10.8 against 7.47–7.77)."""
    m = scores("torque-rig", seed)
    for metric in ("ise", "sd"):
        assert m["adaptive-tv/0.1"][metric] < m["adaptive-const/0.1"][metric], (metric, m)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize(
    ("law", "scenario"),
    [
        ("adaptive-const", "torque-si"),
        ("adaptive-const", "torque-rig"),
        ("adaptive-tv", "torque-rig"),
    ],
)
def test_kappa_reduces_the_peak_error(law: str, scenario: str, seed: int) -> None:
    """TQ §VI: W2 "reduces the peak errors at the transient points" (Tables IV, VII: MAE
    19.2 → 14.8 and 19.7 → 12.7 in simulation, 15.4 → 9.4 and 17.3 → 9.7 on the rig). Nominal,
    seeds 100–109: (50) on torque-si 26.9–28.4 → 21.6–27.2, on torque-rig 86.3–87.3 →
    56.2–62.1; (54) on torque-rig 104.5–107.9 → 62.4–65.6. (54) on torque-si: below."""
    m = scores(scenario, seed)
    assert m[f"{law}/0.1"]["mae"] < m[f"{law}/0.0"]["mae"], m


def test_kappa_shortens_but_sharpens_the_transient_error_of_the_time_varying_law_on_si() -> None:
    """A miss of TQ Table IV (κ = 0.1 lowers the MAE of (54), 19.65 → 12.74): on torque-si
    under the frozen Γ = 10·I it raises the seed-mean MAE (nominal, seeds 100–109: 71.0 →
    86.7 N·m; lower on 4 of 10 seeds). The peak with κ = 0.1 is a spike within 7 ms of the
    set-point steps at 12 and 14 s, where W2 = Φ_f(Φ_fΘ̂ − y) (TQ (47)) acts on the
    instantaneous error at full gain; the error stays above 20 N·m for 5–12 ms per run against
    17–287 ms without κ, on every seed. Both are asserted."""
    assert seed_mean("torque-si", "adaptive-tv/0.1", "mae") > seed_mean(
        "torque-si", "adaptive-tv/0.0", "mae"
    )
    for seed in SEEDS:
        t, err = errors("torque-si", seed)
        inside = (t >= 5.0) & (t <= 30.0)
        above = {
            key: np.count_nonzero(np.abs(err[key][inside]) > 20.0)
            for key in ("adaptive-tv/0.0", "adaptive-tv/0.1")
        }
        assert above["adaptive-tv/0.1"] < above["adaptive-tv/0.0"], (seed, above)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("law", ["adaptive-const", "adaptive-tv"])
def test_kappa_reduces_ise_and_sd_on_the_rig(law: str, seed: int) -> None:
    """TQ Table VII: ISE and SD fall when κ goes from 0 to 0.1, for both laws. Nominal, seeds
    100–109: (50) ISE 4499–5318 → 2311–2938, SD 13.4–14.6 → 9.61–10.8; (54) ISE 5090–5247 →
    1413–1532, SD 14.1–14.3 → 7.47–7.77."""
    m = scores("torque-rig", seed)
    for metric in ("ise", "sd"):
        assert m[f"{law}/0.1"][metric] < m[f"{law}/0.0"][metric], (metric, m)


@pytest.mark.parametrize("seed", SEEDS)
def test_kappa_reduces_ise_and_sd_of_the_time_varying_law_on_si(seed: int) -> None:
    """TQ Table IV: κ = 0.1 lowers ISE and SD of (54) (1.72e5 → 7.49e4, 2.76 → 1.82). Under
    the frozen Γ = 10·I it does on every torque-si seed (nominal, seeds 100–109: ISE 172–2534
    → 149–199, SD 2.62–10.1 → 2.45–2.82; without κ the law drifts on most seeds)."""
    m = scores("torque-si", seed)
    for metric in ("ise", "sd"):
        assert m["adaptive-tv/0.1"][metric] < m["adaptive-tv/0.0"][metric], (metric, m)


@pytest.mark.parametrize("seed", SEEDS)
def test_kappa_raises_ise_and_sd_of_the_constant_gain_on_si(seed: int) -> None:
    """A miss of TQ Table IV (κ = 0.1 lowers ISE and SD of (50), 1.55e5 → 1.33e5, 2.62 →
    2.43): on torque-si it raises them on every held-out seed (nominal, seeds 100–109: ISE
    213–219 → 357–432, SD 2.92–2.96 → 3.78–4.16), while it lowers the MAE (above).
    The likely cause: (50) with ṁ_ai in kg/s adapts θ1 alone (estimation/torque/config.py),
    at the rate Γ1·κ·Φ_f1² ≈ 5·10⁴ s⁻¹ on κW2, so θ̂1 follows the instantaneous
    y = J(N − N_f)/k + τ_lf, whose speed-noise term (J/k)·w1 is ≈ 7 N·m SD with a 0.15 kg·m²
    crank train (docs/estimators.md#dev-tq-kappa-50-si)."""
    m = scores("torque-si", seed)
    for metric in ("ise", "sd"):
        assert m["adaptive-const/0.1"][metric] > m["adaptive-const/0.0"][metric], (metric, m)


def test_paper_diagonal_gain_destabilises_the_time_varying_law() -> None:
    """Why AdaptiveTvConfig's Γ is scalar: TQ's Γ = diag(0.1, 100) (stated for (50)) breaks
    Theorem 4's Lyapunov argument, and on torque-si (54) with κ = 0.1 diverges with it."""
    sc = get_scenario("torque-si")
    data = sc.build(seed=100, mismatch="nominal")
    cfg = sc.default_config("adaptive-tv", data=data) | {"kappa": 0.1}
    assert AdaptiveTvConfig(**cfg).gamma[0] == AdaptiveTvConfig(**cfg).gamma[1]
    with np.errstate(all="ignore"):
        paper = build("adaptive-tv", **cfg, gamma=(0.1, 100.0)).fit(data.signals).outputs
        ours = build("adaptive-tv", **cfg).fit(data.signals).outputs
    assert not np.all(np.abs(paper["theta1"]) < 1e6)  # non-finite or runaway
    assert np.all(np.abs(ours["theta1"]) < 1e2)
