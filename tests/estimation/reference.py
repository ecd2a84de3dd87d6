"""Slow, obvious references of the five map filters (docs/algorithms.md §1–2).

Plain numpy, dense matrices, one sample at a time, written from the equations and not from
the kernels. Locked cells are known constants, so the covariance references remove them from
the state: they estimate only the unlocked cells from ``y' = y − Σ_locked ψ_i θ_i``.

Status codes: 0 accepted, 1 rejected by the accept mask, 2 by the innovation gate, 3 not
usable (before the sensor delay is filled).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from tests.factories import Problem


@dataclass
class Result:
    theta: np.ndarray  # (p,)
    P: np.ndarray | None  # (p, p) or (p+1, p+1) with the sensor state last
    variance: np.ndarray | None  # (p,)
    prediction: np.ndarray  # (n,)
    status: np.ndarray  # (n,)
    y_m: float | None = None
    active: set[int] | None = None

    @property
    def n_mask(self) -> int:
        return int(np.sum(self.status == 1))

    @property
    def n_gate(self) -> int:
        return int(np.sum(self.status == 2))


def locate(g: np.ndarray, u: float) -> tuple[int, float]:
    """Cell ``i`` with ``g[i] ≤ u < g[i+1]`` and ``η``; clamped to the edges outside."""
    if u <= g[0]:
        return 0, 0.0
    if u >= g[-1]:
        return len(g) - 2, 1.0
    for i in range(len(g) - 1):
        if g[i] <= u < g[i + 1]:
            return i, (u - g[i]) / (g[i + 1] - g[i])
    raise AssertionError("unreachable")


def regressor(breakpoints: list[np.ndarray], u: np.ndarray) -> tuple[list[int], list, list]:
    """The 2^d flat C-order indices, their weights and ``η`` per axis for one input."""
    shape = tuple(len(g) for g in breakpoints)
    located = [locate(np.asarray(g), float(x)) for g, x in zip(breakpoints, u, strict=True)]
    cells = [c for c, _ in located]
    etas = [e for _, e in located]
    indices, weights = [], []
    for corner in itertools.product((0, 1), repeat=len(shape)):
        pos = tuple(c + b for c, b in zip(cells, corner, strict=True))
        indices.append(int(np.ravel_multi_index(pos, shape)))
        weights.append(math.prod(e if b else 1.0 - e for e, b in zip(etas, corner, strict=True)))
    return indices, weights, etas


def dense_psi(breakpoints: list[np.ndarray], u: np.ndarray) -> tuple[np.ndarray, set[int]]:
    """Dense regressor ψ (length p) and the active set (every corner, even zero-weight)."""
    p = math.prod(len(g) for g in breakpoints)
    indices, weights, _ = regressor(breakpoints, u)
    psi = np.zeros(p)
    for j, wj in zip(indices, weights, strict=True):
        psi[j] += wj
    return psi, set(indices)


def evaluate(breakpoints: list[np.ndarray], values: np.ndarray, u: np.ndarray) -> float:
    psi, _ = dense_psi(breakpoints, u)
    return float(psi @ np.asarray(values).ravel())


def _steps(problem: Problem):
    """Yield ``(i, u, y, accepted)`` for kernel step ``i`` (``u[i]`` with ``y[i+τ]``)."""
    tau = problem.sensor.delay if problem.sensor is not None else 0
    accept = np.ones(problem.n, bool) if problem.accept is None else problem.accept
    for i in range(problem.n - tau):
        yield i, problem.U[i], problem.y[i + tau], bool(accept[i + tau] and accept[i])


def _pad(problem: Problem, prediction: list, status: list) -> tuple[np.ndarray, np.ndarray]:
    tau = problem.sensor.delay if problem.sensor is not None else 0
    return (
        np.concatenate([np.full(tau, np.nan), prediction]),
        np.concatenate([np.full(tau, 3), status]).astype(int),
    )


def covariance_filter(problem: Problem, kind: str) -> Result:
    """KF, SKF (dense, eager aging, cross-covariances forgotten) or local RLS.

    * ``kf``: ``P ← P + Q`` (after ``F P Fᵀ`` with a sensor), cap, update.
    * ``skf``: as KF, but first zero every off-diagonal ``P_ij`` unless ``i`` and ``j`` are
      both in ``A_{k−1} ∩ A_k`` (``y_M`` always active; ``A_0 = ∅``).
    * ``rls``: as SKF without process noise; ``P_AA ← P_AA / λ`` on the active unlocked
      block; ``s = 1 + ψᵀPψ``; the gate compares ``e²`` with ``K²σv²s``.
    """
    assert kind in ("kf", "skf", "rls")
    sensor = problem.sensor if kind != "rls" else None
    p = problem.size
    locked = problem.locked
    free = np.flatnonzero(~locked)
    nf = free.size
    m = nf + (1 if sensor is not None else 0)
    theta_locked = problem.theta0[locked]
    x = problem.theta0[free].copy()
    P = np.diag(problem.p0[free])
    if sensor is not None:
        tau = sensor.delay
        x = np.append(x, problem.y[tau])
        P = np.pad(P, ((0, 1), (0, 1)))
        P[-1, -1] = problem.sigma_v**2
    q = np.zeros(m)
    q[:nf] = 0.0 if kind == "rls" else problem.sigma_w[free] ** 2
    if sensor is not None:
        q[-1] = sensor.sigma_f**2
    r = 1.0 if kind == "rls" else problem.sigma_v**2
    gate2 = math.inf if problem.gate_sigma is None else problem.gate_sigma**2
    if kind == "rls":
        gate2 *= problem.sigma_v**2
    prev_active: set[int] = set()
    prediction, status = [], []
    for _, u, y, accepted in _steps(problem):
        psi, active = dense_psi(problem.breakpoints, u)
        psi_free = psi[free]
        known = psi[locked] @ theta_locked  # output of the locked cells
        if kind in ("skf", "rls"):
            both = np.isin(free, list(active & prev_active))
            if sensor is not None:
                both = np.append(both, True)
            P = P * (np.outer(both, both) | np.eye(m, dtype=bool))
            prev_active = active
        if sensor is not None:
            a = sensor.lag
            F = np.eye(m)
            F[-1, :nf] = (1 - a) * psi_free
            F[-1, -1] = a
            x[-1] = a * x[-1] + (1 - a) * (psi_free @ x[:nf] + known)
            P = F @ P @ F.T
        if kind == "rls":
            block = np.isin(free, list(active))
            P[np.outer(block, block)] /= problem.forgetting
        P = P + np.diag(q)
        if problem.limit:
            d = np.ones(m)
            p0 = problem.p0[free]
            over = np.diag(P)[:nf] > p0
            d[:nf][over] = np.sqrt(p0[over] / np.diag(P)[:nf][over])
            P = np.diag(d) @ P @ np.diag(d)
        if sensor is not None:
            h = np.zeros(m)
            h[-1] = 1.0
            yhat = x[-1]
        else:
            h = psi_free
            yhat = psi_free @ x + known
        prediction.append(yhat)
        e = y - yhat
        s = h @ P @ h + r
        if not accepted:
            status.append(1)
            continue
        if e * e > gate2 * s:
            status.append(2)
            continue
        K = P @ h / s
        x = x + K * e
        P = (np.eye(m) - np.outer(K, h)) @ P
        status.append(0)
    theta = problem.theta0.copy()
    theta[free] = x[:nf]
    full = np.diag(problem.p0)
    full[np.ix_(free, free)] = P[:nf, :nf]
    if sensor is not None:
        full = np.pad(full, ((0, 1), (0, 1)))
        full[free, -1] = P[:nf, -1]
        full[-1, free] = P[-1, :nf]
        full[-1, -1] = P[-1, -1]
    pred, stat = _pad(problem, prediction, status)
    return Result(
        theta=theta,
        P=full,
        variance=np.diag(full)[:p].copy(),
        prediction=pred,
        status=stat,
        y_m=float(x[-1]) if sensor is not None else None,
        active=prev_active,
    )


def sskf_gain(eta: float, r: float) -> float:
    """Steady-state gain of the element of weight 1 − η (SKF (16); docs/algorithms.md §2.3)."""
    c = 1.0 - 2.0 * eta + 2.0 * eta**2
    s = math.sqrt(1.0 + 4.0 * r / c)
    return 0.5 * (1.0 - eta) * (1.0 + s) / (0.5 * (1.0 + s) * c + r)


def riccati_gain_1d(eta: float, sigma_w2: float, sigma_v2: float) -> np.ndarray:
    """Limit of the 2-element Riccati recursion with ``q = [1−η, η]`` (the gain vector)."""
    q = np.array([1.0 - eta, eta])
    P = np.zeros((2, 2))
    K = np.zeros(2)
    for _ in range(100_000):
        P = P + sigma_w2 * np.eye(2)
        s = q @ P @ q + sigma_v2
        K_new = P @ q / s
        P = P - np.outer(K_new, q @ P)
        if np.max(np.abs(K_new - K)) < 1e-15:
            return K_new
        K = K_new
    raise AssertionError("Riccati recursion did not converge")


def gain_filter(problem: Problem, kind: str) -> Result:
    """SSKF (product of 1-D steady-state gains) or NLMS; the gate uses ``s = σv²``."""
    assert kind in ("sskf", "nlms")
    theta = problem.theta0.copy()
    locked = problem.locked
    sigma_w2 = np.where(locked, 0.0, problem.sigma_w**2)
    sigma_v2 = problem.sigma_v**2
    gate2 = math.inf if problem.gate_sigma is None else problem.gate_sigma**2
    prediction, status = [], []
    for _, u, y, accepted in _steps(problem):
        indices, weights, etas = regressor(problem.breakpoints, u)
        yhat = sum(wc * theta[j] for j, wc in zip(indices, weights, strict=True))
        prediction.append(yhat)
        e = y - yhat
        if not accepted:
            status.append(1)
            continue
        if e * e > gate2 * sigma_v2:
            status.append(2)
            continue
        status.append(0)
        free = [(c, j) for c, j in enumerate(indices) if not locked[j]]
        if kind == "nlms":
            norm = sum(wc**2 for wc in weights) + problem.eps  # all active cells, locked too
            for c, j in free:
                theta[j] += problem.mu * weights[c] * e / norm
            continue
        total_w2 = sum(wc * sigma_w2[j] for j, wc in zip(indices, weights, strict=True))
        if total_w2 == 0.0:
            continue
        r = sigma_v2 / total_w2
        corners = list(itertools.product((0, 1), repeat=len(etas)))
        for c, j in free:
            gain = 1.0
            for eta, upper in zip(etas, corners[c], strict=True):
                gain *= sskf_gain(1.0 - eta, r) if upper else sskf_gain(eta, r)
            theta[j] += gain * e
    pred, stat = _pad(problem, prediction, status)
    return Result(theta=theta, P=None, variance=None, prediction=pred, status=stat)


def reference(problem: Problem, kind: str) -> Result:
    if kind in ("sskf", "nlms"):
        return gain_filter(problem, kind)
    return covariance_filter(problem, kind)
