"""Full Kalman filter over a look-up table (docs/algorithms.md §2.1, §2.5, §2.6; SKF §4.4).

State ``x`` is ``θ`` (length p) or, with sensor dynamics, the wide state ``[θ; y_M]``
(length p+1, SKF (26)–(28)); ``P`` is the matching dense covariance. The regressor is sparse
(``2^d`` active elements), so ``Pψ`` is a gather and the update a rank-1 correction: O(p²)
per sample, never O(p³).
"""

import numba as nb
import numpy as np

from estimation.kernels.specialise import fixed_or

ACCEPTED = 0
REJECTED_MASK = 1
REJECTED_GATE = 2


@nb.njit(cache=True, inline="always")
def _cap_row_col(P: np.ndarray, i: int, cap: float) -> None:
    """PSD-preserving covariance limit (docs/algorithms.md §2.5): scale row and column ``i`` by
    ``sqrt(cap / P_ii)`` so ``P_ii = cap`` exactly and ``P`` stays PSD (``D P D`` form)."""
    f = np.sqrt(cap / P[i, i])
    m = P.shape[0]
    for j in range(m):
        P[i, j] *= f
    for j in range(m):
        P[j, i] *= f
    P[i, i] = cap


@nb.njit(cache=True)
def kf_kernel(
    x: np.ndarray,
    P: np.ndarray,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    sigma_w2: np.ndarray,
    sigma_v2: float,
    p0: np.ndarray,
    limit: bool,
    locked: np.ndarray,
    gate2: float,
    has_sensor: bool,
    lag: float,
    sigma_f2: float,
    yhat_out: np.ndarray,
    status_out: np.ndarray,
    s_out: np.ndarray,
    corners: tuple,
) -> None:
    """Run the full KF over ``n`` samples, updating ``x`` and ``P`` in place.

    Per sample ``k`` (ψ = ``(idx[k], w[k])``; ψ_u = ψ with locked weights zeroed, so locked
    cells act as known constants — their values, variances and zero cross-covariances never
    change):

    * sensor dynamics (SKF (25)–(33)): ``y_M ← a y_M + (1−a) ψᵀθ``,
      ``P ← F P Fᵀ`` with ``F = [[I, 0], [(1−a) ψ_uᵀ, a]]``, then ``P_yy += σf²``;
    * predict (SKF (11a)): ``P_ii += σw²_i``; with ``limit``, cap ``P_ii`` at ``P0_ii``;
    * innovation ``e = y − ŷ`` with ``ŷ = ψᵀθ`` (or ``y_M``) and ``s = hᵀPh + σv²``;
    * skip the update if ``accept[k]`` is false or ``e² > gate2·s`` (normalised innovation gate);
    * update (SKF (7)): ``g = Ph/s``, ``x ← x + g e``, ``P ← P − (Ph)(Ph)ᵀ/s``.

    ``sigma_w2`` must already be zero on locked cells. Writes the prediction ``ŷ`` and the
    sample status (0 accepted, 1 rejected by mask, 2 rejected by gate) and the innovation
    variance ``s`` (for the innovation statistics of docs/tuning.md) to the out arrays.
    ``corners`` is the size token of :mod:`estimation.kernels.specialise` (``2^d`` or generic).
    """
    n = y.shape[0]
    p = sigma_w2.shape[0]
    m = x.shape[0]
    nc = fixed_or(corners, idx.shape[1])
    ym = m - 1
    b = 1.0 - lag
    v = np.empty(m)
    wu = np.empty(nc)
    for k in range(n):
        for c in range(nc):
            wu[c] = 0.0 if locked[idx[k, c]] else w[k, c]
        if has_sensor:
            pred = 0.0
            for c in range(nc):
                pred += w[k, c] * x[idx[k, c]]
            # v = Pθθ ψ_u, gathered by rows (P is symmetric) for contiguous access.
            for i in range(p):
                v[i] = 0.0
            hc = 0.0
            for c in range(nc):
                j = idx[k, c]
                wc = wu[c]
                if wc != 0.0:
                    for i in range(p):
                        v[i] += wc * P[j, i]
                    hc += wc * P[j, ym]
            hPh = 0.0
            for c in range(nc):
                hPh += wu[c] * v[idx[k, c]]
            pyy = b * b * hPh + 2.0 * lag * b * hc + lag * lag * P[ym, ym]
            for i in range(p):
                cross = b * v[i] + lag * P[i, ym]
                P[i, ym] = cross
                P[ym, i] = cross
            P[ym, ym] = pyy + sigma_f2
            x[ym] = lag * x[ym] + b * pred
        for i in range(p):
            P[i, i] += sigma_w2[i]
        if limit:
            for i in range(p):
                if P[i, i] > p0[i]:
                    _cap_row_col(P, i, p0[i])
        if has_sensor:
            yhat = x[ym]
            for i in range(m):
                v[i] = P[i, ym]
            s = P[ym, ym] + sigma_v2
        else:
            yhat = 0.0
            for c in range(nc):
                yhat += w[k, c] * x[idx[k, c]]
            for i in range(m):
                v[i] = 0.0
            for c in range(nc):
                j = idx[k, c]
                wc = wu[c]
                if wc != 0.0:
                    for i in range(m):
                        v[i] += wc * P[j, i]
            s = sigma_v2
            for c in range(nc):
                s += wu[c] * v[idx[k, c]]
        yhat_out[k] = yhat
        s_out[k] = s
        if not accept[k]:
            status_out[k] = REJECTED_MASK
            continue
        e = y[k] - yhat
        if e * e > gate2 * s:
            status_out[k] = REJECTED_GATE
            continue
        inv_s = 1.0 / s
        ge = e * inv_s
        for i in range(m):
            x[i] += v[i] * ge
        # (v_i v_j) is commutative, so P stays exactly symmetric.
        for i in range(m):
            vi = v[i]
            if vi != 0.0:
                for j in range(m):
                    P[i, j] -= (vi * v[j]) * inv_s
        status_out[k] = ACCEPTED
