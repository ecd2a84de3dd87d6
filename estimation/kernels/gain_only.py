"""Covariance-free map updates: steady-state KF (SSKF) and normalised LMS.

Both update only the active elements, ``θ_A ← θ_A + K e``, with a gain that depends on the
interpolation weights alone.
"""

import numba as nb
import numpy as np

from estimation.kernels.kalman import ACCEPTED, REJECTED_GATE, REJECTED_MASK
from estimation.kernels.specialise import fixed_or


@nb.njit(cache=True, inline="always")
def sskf_gain_1d(eta: float, r: float) -> float:
    """Steady-state gain of the element with weight ``1−η`` (SKF (16), as restated in
    docs/algorithms.md §2.3): ``c = 1 − 2η + 2η²``, ``s = sqrt(1 + 4r/c)``,
    ``k = 0.5(1−η)(1+s) / (0.5(1+s)c + r)`` with ``r = σv²/σw²``."""
    c = 1.0 - 2.0 * eta + 2.0 * eta * eta
    s = np.sqrt(1.0 + 4.0 * r / c)
    return 0.5 * (1.0 - eta) * (1.0 + s) / (0.5 * (1.0 + s) * c + r)


@nb.njit(cache=True)
def sskf_kernel(
    theta: np.ndarray,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    sigma_w2: np.ndarray,
    sigma_v2: float,
    locked: np.ndarray,
    gate2: float,
    yhat_out: np.ndarray,
    status_out: np.ndarray,
    corners: tuple,
) -> None:
    """SSKF over ``n`` samples (SKF §4.5, (15)–(16), Algorithm 2).

    Per axis ``a``, ``η_a`` is the total weight of the corners on the upper breakpoint; the
    gain of corner ``c`` is the product over axes of ``k(η_a)`` (lower breakpoint) or
    ``k(1−η_a)`` (upper), the paper's product form (15), with ``r = σv² / σ̄w²`` where ``σ̄w²``
    is the weight-averaged process variance of the active cells. Locked cells get zero gain.
    The innovation gate uses ``s = σv²``. ``corners`` is the size token of
    :mod:`estimation.kernels.specialise` (``2^d`` or generic).
    """
    n = y.shape[0]
    nc = fixed_or(corners, idx.shape[1])
    d = 0
    while (1 << d) < nc:
        d += 1
    k_lower = np.empty(d)
    k_upper = np.empty(d)
    for k in range(n):
        yhat = 0.0
        sw = 0.0
        for c in range(nc):
            yhat += w[k, c] * theta[idx[k, c]]
            sw += w[k, c] * sigma_w2[idx[k, c]]
        yhat_out[k] = yhat
        if not accept[k]:
            status_out[k] = REJECTED_MASK
            continue
        e = y[k] - yhat
        if e * e > gate2 * sigma_v2:
            status_out[k] = REJECTED_GATE
            continue
        status_out[k] = ACCEPTED
        if sw <= 0.0:
            continue  # every active cell is locked: nothing may change
        r = sigma_v2 / sw
        for a in range(d):
            eta = 0.0
            for c in range(nc):
                if (c >> (d - 1 - a)) & 1:
                    eta += w[k, c]
            eta = min(max(eta, 0.0), 1.0)
            k_lower[a] = sskf_gain_1d(eta, r)
            k_upper[a] = sskf_gain_1d(1.0 - eta, r)
        for c in range(nc):
            j = idx[k, c]
            if locked[j]:
                continue
            gain = 1.0
            for a in range(d):
                gain *= k_upper[a] if (c >> (d - 1 - a)) & 1 else k_lower[a]
            theta[j] += gain * e


@nb.njit(cache=True)
def nlms_kernel(
    theta: np.ndarray,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    mu: float,
    eps: float,
    sigma_v2: float,
    locked: np.ndarray,
    gate2: float,
    yhat_out: np.ndarray,
    status_out: np.ndarray,
    corners: tuple,
) -> None:
    """Normalised LMS (docs/algorithms.md §2.4): ``θ_c += μ q_c e / (qᵀq + ε)`` for each unlocked
    active cell ("distribute the error over the active cells"). ``qᵀq`` sums over every active
    cell, locked ones included, so a lone unlocked corner with a tiny weight takes a share of
    the error, not all of it divided by its weight. The innovation gate uses ``s = σv²``.
    ``corners`` is the size token of :mod:`estimation.kernels.specialise`."""
    n = y.shape[0]
    nc = fixed_or(corners, idx.shape[1])
    for k in range(n):
        yhat = 0.0
        qq = 0.0
        for c in range(nc):
            j = idx[k, c]
            yhat += w[k, c] * theta[j]
            qq += w[k, c] * w[k, c]
        yhat_out[k] = yhat
        if not accept[k]:
            status_out[k] = REJECTED_MASK
            continue
        e = y[k] - yhat
        if e * e > gate2 * sigma_v2:
            status_out[k] = REJECTED_GATE
            continue
        status_out[k] = ACCEPTED
        step = mu * e / (qq + eps)
        for c in range(nc):
            j = idx[k, c]
            if not locked[j]:
                theta[j] += step * w[k, c]
