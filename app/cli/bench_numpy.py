"""Plain-numpy implementations of the map filters, the yardstick of ``mapwise bench``.

Each function runs the same update as its compiled kernel (docs/algorithms.md §2) on the
same regressor rows, one sample at a time with vectorised numpy inside the step: what a
careful numpy user would write. They cover the benchmark's configuration only (no locked
cells, no gate, no mask, no covariance limit, no sensor model) and return the map, so the
benchmark can check they agree with the kernels before comparing speed.
"""

from __future__ import annotations

import numpy as np


def kf(
    theta: np.ndarray, P: np.ndarray, idx: np.ndarray, w: np.ndarray, y: np.ndarray, *,
    sigma_w2: np.ndarray, sigma_v2: float,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Full KF (SKF (7), (11a)): ``P += diag(σw²)``, ``v = P ψ``, ``s = ψᵀv + σv²``,
    ``θ += v e/s``, ``P −= v vᵀ/s``; ``ψ`` is sparse, so ``P ψ`` is a gather of columns."""
    theta, P = theta.copy(), P.copy()
    diag = np.diag_indices_from(P)
    for k in range(y.size):
        a, q = idx[k], w[k]
        P[diag] += sigma_w2
        v = P[:, a] @ q
        s = q @ v[a] + sigma_v2
        e = y[k] - q @ theta[a]
        theta += v * (e / s)
        P -= np.outer(v, v) / s
    return theta, P


def local(
    theta: np.ndarray, idx: np.ndarray, w: np.ndarray, y: np.ndarray, *, p0: np.ndarray,
    sigma_w2: np.ndarray, r: float, forget: float = 1.0,
) -> np.ndarray:  # fmt: skip
    """SKF (``forget = 1``, ``r = σv²``) or local RLS (``σw² = 0``, ``r = 1``, ``forget = λ``)
    with lazily aged variances (docs/algorithms.md §2.2, §2.4): when the active cells change,
    leaving cells keep their variance, entering ones are aged by ``σw²·(steps missed)`` and
    only covariances between cells in both sets survive."""
    theta = theta.copy()
    var = p0.copy()
    last = np.full(theta.size, -1)
    active = np.full(idx.shape[1], -1)
    Pa = np.zeros((idx.shape[1], idx.shape[1]))
    for k in range(y.size):
        a, q = idx[k], w[k]
        if np.any(a != active):
            leaving = ~np.isin(active, a) & (active >= 0)
            var[active[leaving]] = np.diag(Pa)[leaving]
            last[active[leaving]] = k - 1
            pos = np.array([int(np.flatnonzero(active == j)[0]) if j in active else -1 for j in a])
            kept = pos >= 0
            fresh = np.zeros_like(Pa)
            fresh[np.ix_(kept, kept)] = Pa[np.ix_(pos[kept], pos[kept])]
            entering = np.flatnonzero(~kept)
            fresh[entering, entering] = var[a[entering]] + sigma_w2[a[entering]] * (
                k - 1 - last[a[entering]]
            )
            Pa, active = fresh, a.copy()
        if forget != 1.0:
            Pa /= forget
        Pa[np.diag_indices_from(Pa)] += sigma_w2[a]
        v = Pa @ q
        s = q @ v + r
        e = y[k] - q @ theta[a]
        theta[a] += v * (e / s)
        Pa -= np.outer(v, v) / s
    return theta


def sskf(
    theta: np.ndarray, idx: np.ndarray, w: np.ndarray, y: np.ndarray, *,
    sigma_w2: np.ndarray, sigma_v2: float,
) -> np.ndarray:  # fmt: skip
    """SSKF (SKF (15)–(16)): the gain of a corner is the product over axes of the 1-D
    steady-state gain ``k(η)`` or ``k(1−η)``, with ``r = σv²/σ̄w²``."""
    theta = theta.copy()
    nc = idx.shape[1]
    d = nc.bit_length() - 1
    upper = (np.arange(nc)[:, None] >> (d - 1 - np.arange(d))[None, :]) & 1 == 1  # (nc, d)
    for k in range(y.size):
        a, q = idx[k], w[k]
        e = y[k] - q @ theta[a]
        r = sigma_v2 / (q @ sigma_w2[a])
        eta = np.clip(q @ upper, 0.0, 1.0)
        gains = np.where(upper, _gain_1d(1.0 - eta, r), _gain_1d(eta, r)).prod(axis=1)
        theta[a] += gains * e
    return theta


def nlms(
    theta: np.ndarray, idx: np.ndarray, w: np.ndarray, y: np.ndarray, *, mu: float, eps: float
) -> np.ndarray:
    """Normalised LMS (docs/algorithms.md §2.4): ``θ_A += μ q e / (qᵀq + ε)``."""
    theta = theta.copy()
    for k in range(y.size):
        a, q = idx[k], w[k]
        e = y[k] - q @ theta[a]
        theta[a] += (mu * e / (q @ q + eps)) * q
    return theta


def _gain_1d(eta: np.ndarray, r: float) -> np.ndarray:
    """SKF (16): ``k = 0.5(1−η)(1+s) / (0.5(1+s)c + r)``, ``c = 1−2η+2η²``, ``s = √(1+4r/c)``."""
    c = 1.0 - 2.0 * eta + 2.0 * eta * eta
    s = np.sqrt(1.0 + 4.0 * r / c)
    return 0.5 * (1.0 - eta) * (1.0 + s) / (0.5 * (1.0 + s) * c + r)
