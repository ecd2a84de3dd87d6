"""LPV adaptive observer of a MAF-sensor error map (LPV (26), (36); docs/algorithms.md §3).

The continuous observer, in the scaled coordinates of :mod:`estimation.observers.lmi`
(``x = S_x x̃``, ``y = S_y ỹ``, ``θ = S_y[2] θ̃``), restricted to the ``m = 2^d`` active
elements ``θ_A`` of ``ψ(υ_k)``, is linear in ``z = (x̃, θ̃_A)`` over one sample:

    x̃' = (Ã − L̃C̃) x̃ − L̃ G̃ ψ_Aᵀ θ̃_A + Ẽ + L̃ ỹ
    θ̃_A' = Γ_A ψ_A (ỹ3 − C̃2 x̃ − ψ_Aᵀ θ̃_A)

It is stiff (closed-loop eigenvalues of a few hundred 1/s, and ``Γψ²`` up to ``γ`` — the
paper's 200 1/s — at a 10 Hz data rate), so each sample is integrated by **backward
(implicit) Euler** with the sample's ρ, y, E held: ``(I − hM_k) z_k = z_{k−1} + h b_k``.
Backward Euler is L-stable: every mode of a Hurwitz ``M_k`` is damped for any ``h > 0`` (the
stiff modes settle to their quasi-steady state within the sample), so the discretisation
cannot go unstable.

The adaptation gain ``Γ = diag(g_j)`` (LPV (26) allows any positive definite diagonal Γ):

- ``NORMALISED`` — ``g_j = (1/γ + S_j)⁻¹`` with ``S_j = ∫ψ_j² dt`` [s] the excitation element
  ``j`` has received so far: each element starts at the gain ``γ`` and then averages like a
  running least-squares mean, so white sensor noise is averaged out instead of being copied
  into the map (ours; see :mod:`estimation.observers.lpv`);
- ``CONSTANT`` — ``g_j = γ`` (the paper's ``Γ = γI``).
"""

import numba as nb
import numpy as np

CONSTANT = 0
NORMALISED = 1


@nb.njit(cache=True)
def _solve_inplace(M: np.ndarray, b: np.ndarray, n: int) -> None:
    """Gaussian elimination with partial pivoting on the leading ``n×n`` block; ``b`` ← x."""
    for c in range(n):
        piv = c
        best = abs(M[c, c])
        for r in range(c + 1, n):
            if abs(M[r, c]) > best:
                best = abs(M[r, c])
                piv = r
        if piv != c:
            for j in range(n):
                tmp = M[c, j]
                M[c, j] = M[piv, j]
                M[piv, j] = tmp
            tmp = b[c]
            b[c] = b[piv]
            b[piv] = tmp
        inv = 1.0 / M[c, c]
        for r in range(c + 1, n):
            f = M[r, c] * inv
            if f != 0.0:
                for j in range(c, n):
                    M[r, j] -= f * M[c, j]
                b[r] -= f * b[c]
    for c in range(n - 1, -1, -1):
        s = b[c]
        for j in range(c + 1, n):
            s -= M[c, j] * b[j]
        b[c] = s / M[c, c]


@nb.njit(cache=True)
def lpv_observer_kernel(
    x_hat: np.ndarray,
    theta: np.ndarray,
    weight_sum: np.ndarray,
    excitation: np.ndarray,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    rho: np.ndarray,
    e: np.ndarray,
    h: np.ndarray,
    accept: np.ndarray,
    L_scaled: np.ndarray,
    sx: np.ndarray,
    sy: np.ndarray,
    rho_lo: np.ndarray,
    rho_hi: np.ndarray,
    a1: float,
    a2: float,
    gamma: float,
    mode: int,
    x_out: np.ndarray,
    wc_out: np.ndarray,
    dwc_out: np.ndarray,
) -> None:
    """Run the observer over ``n`` samples, updating ``x_hat``, ``theta``, ``weight_sum``,
    ``excitation`` in place.

    Shapes: ``x_hat`` (3,) [Pa, Pa, rad/s]; ``theta`` (p,) [kg/s]; ``weight_sum`` (p,)
    accumulated ψ weights of accepted samples; ``excitation`` (p,) ``S_j = Σ h ψ_j²`` [s] of
    accepted samples; ``idx``/``w`` (n, m); ``y`` (n, 3) measured ``(p_im, ω_t, W_c,meas)``;
    ``rho`` (n, 5), clipped to ``[rho_lo, rho_hi]`` (the box the gain was designed for);
    ``e`` (n, 3) the known input ``E`` of LPV (4); ``h`` (n,) step to each sample [s]
    (0: no propagation); ``accept`` (n,) — a rejected sample propagates ``x̂`` with ``θ``
    frozen; ``gamma`` and ``mode`` (``CONSTANT``/``NORMALISED``) set ``Γ``. Writes ``x_out``
    (n, 3), ``wc_out`` = ``ρ1 x̂3`` (estimated true ``W_c``) and ``dwc_out`` = ``ψᵀθ̂``
    (estimated ``ΔW_c``) after each sample.
    """
    n = y.shape[0]
    m = idx.shape[1]
    nz = 3 + m
    M = np.zeros((nz, nz))
    z = np.zeros(nz)
    A = np.zeros((3, 3))
    C = np.zeros((3, 3))
    r = np.zeros(5)
    g = np.zeros(m)
    s_theta = sy[2]
    for k in range(n):
        for i in range(5):
            r[i] = min(max(rho[k, i], rho_lo[i]), rho_hi[i])
        # Scaled A(ρ) = S_x⁻¹ A S_x and C(ρ) = S_y⁻¹ C S_x (LPV (4)–(5), (25)).
        A[0, 0] = -a1 * r[2]
        A[0, 1] = a1 * r[1] * sx[1] / sx[0]
        A[0, 2] = a1 * r[0] * sx[2] / sx[0]
        A[1, 0] = a2 * r[2] * sx[0] / sx[1]
        A[1, 1] = -a2 * (r[1] + r[3])
        A[2, 2] = -r[4]
        C[0, 0] = sx[0] / sy[0]
        C[1, 2] = sx[2] / sy[1]
        C[2, 2] = r[0] * sx[2] / sy[2]
        hk = h[k]
        for c in range(m):
            if not accept[k]:
                g[c] = 0.0
            elif mode == NORMALISED:
                g[c] = 1.0 / (1.0 / gamma + excitation[idx[k, c]])
            else:
                g[c] = gamma
        for i in range(3):
            z[i] = x_hat[i] / sx[i]
        for c in range(m):
            z[3 + c] = theta[idx[k, c]] / s_theta
        if hk > 0.0:
            # M = [[A − LC, −L G ψᵀ], [−Γψ C2, −Γψψᵀ]];  b = [E + L y, Γψ y3].
            for i in range(3):
                for j in range(3):
                    lc = 0.0
                    for q in range(3):
                        lc += L_scaled[i, q] * C[q, j]
                    M[i, j] = -hk * (A[i, j] - lc)
                M[i, i] += 1.0
                for c in range(m):
                    M[i, 3 + c] = hk * L_scaled[i, 2] * w[k, c]
                ly = 0.0
                for q in range(3):
                    ly += L_scaled[i, q] * y[k, q] / sy[q]
                z[i] += hk * (e[k, i] / sx[i] + ly)
            for c in range(m):
                for j in range(3):
                    M[3 + c, j] = hk * g[c] * w[k, c] * C[2, j]
                for d in range(m):
                    M[3 + c, 3 + d] = hk * g[c] * w[k, c] * w[k, d]
                M[3 + c, 3 + c] += 1.0
                z[3 + c] += hk * g[c] * w[k, c] * y[k, 2] / s_theta
            _solve_inplace(M, z, nz)
        for i in range(3):
            x_hat[i] = z[i] * sx[i]
            x_out[k, i] = x_hat[i]
        dwc = 0.0
        for c in range(m):
            j = idx[k, c]
            if g[c] > 0.0 and hk > 0.0:
                theta[j] = z[3 + c] * s_theta
                weight_sum[j] += w[k, c]
                excitation[j] += hk * w[k, c] * w[k, c]
            dwc += w[k, c] * theta[j]
        wc_out[k] = rho[k, 0] * x_hat[2]
        dwc_out[k] = dwc
