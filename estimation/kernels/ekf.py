"""Joint state and map EKF on the 3-state air path (docs/algorithms.md §4; EKF §2–5): kernels.

The model is the simulator's own air path (W&E (2011), LPV (1)–(2)) restricted to the three
states the EKF estimates, ``x = [p_im, p_em, ω_t]`` (Pa, Pa, rad/s), driven by the measured
actuator positions and engine inputs ``u = [ũ_egr %, ũ_vgt %, u_δ mg/cycle, n_e rpm]``
(columns ``U_*``). Every flow, temperature and efficiency is evaluated by
:func:`estimation.kernels.airpath_plant.airpath_rhs` at the EKF's *own* state estimate, never
from measured pressures: the model needs no ρ computed from sensors. The Seiliger-cycle
memory ``(T_1, x_r)`` is carried along the predicted trajectory and advanced once per
integration step, as the plant does.

Pieces (all over whole arrays, no allocation inside the sample loop):

* :func:`model_rhs`, :func:`model_jacobian` — ``f(x, u) = ẋ`` and ``J = ∂f/∂x`` by central
  differences with steps ``FD_REL·|x_j|`` (verified against a Richardson-extrapolated
  reference in the tests);
* :func:`compressor_flow` — ``W_c(x, u)`` [kg/s] and ``∂W_c/∂x`` (central differences);
* :func:`propagate` — one sample period of exponential Euler, ``x ← x + h φ1(h J) f(x)``
  over ``n_sub`` steps (read off ``exp([[J, f], [0, 0]] h)``), stable however stiff ``J``
  is (the intake manifold pole reaches −500 1/s against ``Δt = 0.1 s``); the transition
  matrix ``Φ = Π exp(h J_i)`` is the solution of the variational equation ``Φ̇ = J Φ``
  along the predicted trajectory (the continuous–discrete EKF's state Jacobian; it matches
  central differences of the whole one-sample map to 10⁻³ in the tests), and the process
  noise is integrated along the same steps;
* :func:`ekf_kernel` — the filter: predict, sequential scalar updates with a χ² innovation
  gate and a line search along the Kalman step (for the compressor-flow kink at
  ``p_im = p_amb``), covariance limiting of the parameter states: PSD-preserving
  (:data:`LIMIT_PSD`, mapwise's default) or the EKF paper's literal diagonal cap
  (:data:`LIMIT_DIAG`).
"""

import math

import numba as nb
import numpy as np

from estimation.kernels import airpath_plant as apk
from estimation.kernels.kalman import _cap_row_col
from estimation.kernels.regressor import _locate

# Covariance limiting of the parameter states (``limit`` of :func:`ekf_kernel`).
LIMIT_NONE = 0
LIMIT_PSD = 1  # P ← D P D, D = I except D_ii = √(P0_ii / P_ii): P_ii = P0_ii, P stays PSD
LIMIT_DIAG = 2  # P_ii ← min(P_ii, P0_ii), off-diagonals untouched (EKF §3.1 as written)

MODE_DEF = 0
MODE_AUG = 1
MODE_MAP = 2

N_X = 3  # p_im, p_em, omega_t

# Columns of the input array U.
U_EGR, U_VGT, U_FUEL, U_SPEED = 0, 1, 2, 3
N_U = 4

# Columns of the measurement array Y (which are used is a per-run mask).
Y_MAF, Y_P_IM, Y_P_EM, Y_OMEGA_T = 0, 1, 2, 3
N_Y = 4

# Layout of the integer ``counts`` array of the filter state.
C_GATE = 0  # C_GATE + j: updates of output j rejected by the innovation gate
C_DAMPED = N_Y  # C_DAMPED + j: updates of output j shortened by the line search (α < 1)
C_CLAMP = 2 * N_Y  # samples whose state estimate left the plant's safety box
N_COUNTS = 2 * N_Y + 1

ARMIJO_C = 1e-4  # sufficient-decrease constant of the update line search
MAX_HALVINGS = 12  # α down to 2⁻¹²; below that the update is dropped (α = 0)

ACCEPTED = 0
REJECTED_MASK = 1
REJECTED_GATE = 2

FD_REL = 1e-6  # relative step of the central differences


@nb.njit(cache=True)
def model_rhs(
    x: np.ndarray,
    u: np.ndarray,
    mem: np.ndarray,
    prm: np.ndarray,
    x8: np.ndarray,
    dx8: np.ndarray,
    alg: np.ndarray,
    f: np.ndarray,
) -> None:
    """``f ← ẋ(x, u)`` [Pa/s, Pa/s, rad/s²] of LPV (1) with the plant's sub-models.

    ``ṗ_im = a1 (W_c + W_egr − W_ei)``, ``ṗ_em = a2 (W_ei + W_f − W_t − W_egr)``,
    ``ω̇_t = (P_t η_m − P_c) / (J_t ω_t)`` at ``x`` with the actuator positions of ``u`` and
    the Seiliger memory ``mem = (T_1 K, x_r)``; ``alg`` receives the sub-model values
    (including the next memory iterate). ``x8``, ``dx8`` are scratch (the plant's 8-state
    layout; the oxygen fractions do not enter ``f``).
    """
    x8[0] = x[0]
    x8[1] = x[1]
    x8[2] = x[2]
    x8[3] = prm[apk.X_OC]
    x8[4] = prm[apk.X_OC]
    x8[5] = u[U_EGR]  # both EGR lag states at the position: ũ_egr = K ũ1 − (K − 1) ũ2 = ũ
    x8[6] = u[U_EGR]
    x8[7] = u[U_VGT]
    apk.airpath_rhs(x8, mem, u[U_FUEL], u[U_SPEED], prm, alg, dx8)
    f[0] = dx8[0]
    f[1] = dx8[1]
    f[2] = dx8[2]


@nb.njit(cache=True)
def model_jacobian(
    x: np.ndarray,
    u: np.ndarray,
    mem: np.ndarray,
    prm: np.ndarray,
    x8: np.ndarray,
    dx8: np.ndarray,
    alg: np.ndarray,
    xs: np.ndarray,
    fp: np.ndarray,
    fm: np.ndarray,
    J: np.ndarray,
) -> None:
    """``J ← ∂f/∂x`` (3×3) by central differences, step ``FD_REL·|x_j|`` (``mem`` held)."""
    for j in range(N_X):
        for i in range(N_X):
            xs[i] = x[i]
        d = FD_REL * abs(x[j])
        xs[j] = x[j] + d
        hi = xs[j]
        model_rhs(xs, u, mem, prm, x8, dx8, alg, fp)
        xs[j] = x[j] - d
        lo = xs[j]
        model_rhs(xs, u, mem, prm, x8, dx8, alg, fm)
        for i in range(N_X):
            J[i, j] = (fp[i] - fm[i]) / (hi - lo)


@nb.njit(cache=True)
def _w_c(x: np.ndarray, u: np.ndarray, mem: np.ndarray, prm: np.ndarray, alg: np.ndarray) -> float:
    apk.airpath_algebra(
        x[0], x[1], x[2], u[U_EGR], u[U_VGT], u[U_FUEL], u[U_SPEED], mem[0], mem[1], prm, alg
    )
    return alg[apk.A_W_C]


@nb.njit(cache=True)
def compressor_flow(
    x: np.ndarray,
    u: np.ndarray,
    mem: np.ndarray,
    prm: np.ndarray,
    alg: np.ndarray,
    xs: np.ndarray,
    grad: np.ndarray,
) -> float:
    """``W_c(x)`` [kg/s] (LPV (2), the plant's compressor model) and ``grad ← ∂W_c/∂x``.

    ``W_c`` depends on ``p_im`` and ``ω_t`` only (``∂/∂p_em = 0``); the two partials are
    central differences with step ``FD_REL·|x_j|``.
    """
    for i in range(N_X):
        xs[i] = x[i]
    grad[1] = 0.0
    for j in (0, 2):
        d = FD_REL * abs(x[j])
        xs[j] = x[j] + d
        hi = xs[j]
        wp = _w_c(xs, u, mem, prm, alg)
        xs[j] = x[j] - d
        lo = xs[j]
        wm = _w_c(xs, u, mem, prm, alg)
        xs[j] = x[j]
        grad[j] = (wp - wm) / (hi - lo)
    return _w_c(x, u, mem, prm, alg)


@nb.njit(cache=True)
def expm_affine(M: np.ndarray, T: np.ndarray, R: np.ndarray, S: np.ndarray) -> None:
    """``R ← exp(M)`` for ``M = [[A, b], [0, 0]]`` (4×4, last row zero; ``R``'s last row is
    then ``[0, 0, 0, 1]``). Scaling and squaring of the Taylor series to order 14 at
    ``‖M/2^s‖∞ ≤ 1/2`` (truncation below 10⁻¹⁵); products skip the zero row, and a square of
    ``[[E, d], [0, 1]]`` is ``[[E², E d + d], [0, 1]]``."""
    n = N_X + 1
    norm = 0.0
    for i in range(N_X):
        row = 0.0
        for j in range(n):
            row += abs(M[i, j])
        norm = max(norm, row)
    s = 0
    while norm > 0.5:
        norm *= 0.5
        s += 1
    scale = 0.5**s
    # R = I + Σ_{j≥1} (M/2^s)^j / j!, accumulated as T_j = T_{j-1} (M/2^s) / j; T_j's last
    # row is zero for j ≥ 1, so only rows 0..2 are formed.
    for i in range(n):
        for j in range(n):
            R[i, j] = 1.0 if i == j else 0.0
    for i in range(N_X):
        for j in range(n):
            T[i, j] = M[i, j] * scale
            R[i, j] += T[i, j]
    for order in range(2, 15):
        f = scale / order
        for i in range(N_X):
            for j in range(n):
                acc = 0.0
                for c in range(N_X):
                    acc += T[i, c] * M[c, j]
                S[i, j] = acc * f
        for i in range(N_X):
            for j in range(n):
                T[i, j] = S[i, j]
                R[i, j] += S[i, j]
    for _ in range(s):
        for i in range(N_X):
            for j in range(n):
                acc = R[i, N_X] if j == N_X else 0.0
                for c in range(N_X):
                    acc += R[i, c] * R[c, j]
                S[i, j] = acc
        for i in range(N_X):
            for j in range(n):
                R[i, j] = S[i, j]


@nb.njit(cache=True)
def clamp_to_box(x: np.ndarray, prm: np.ndarray) -> bool:
    """Project ``x`` onto the plant's safety box (``p_im ≥ 0.3 p_amb``, ``p_em ≥ 0.5 p_amb``,
    ``ω_t ∈ [ω_t,min, ω_t,max]``); True if anything moved."""
    moved = False
    lo = (0.3 * prm[apk.P_AMB], 0.5 * prm[apk.P_AMB], prm[apk.OMEGA_T_MIN])
    for i in range(N_X):
        if x[i] < lo[i]:
            x[i] = lo[i]
            moved = True
    if x[2] > prm[apk.OMEGA_T_MAX]:
        x[2] = prm[apk.OMEGA_T_MAX]
        moved = True
    return moved


@nb.njit(cache=True)
def _congruence(E: np.ndarray, A: np.ndarray, tmp: np.ndarray) -> None:
    """``A ← E[:3, :3] A E[:3, :3]ᵀ`` for symmetric 3×3 ``A`` (kept exactly symmetric)."""
    for i in range(N_X):
        for j in range(N_X):
            acc = 0.0
            for c in range(N_X):
                acc += E[i, c] * A[c, j]
            tmp[i, j] = acc
    for i in range(N_X):
        for j in range(i, N_X):
            acc = 0.0
            for c in range(N_X):
                acc += tmp[i, c] * E[j, c]
            A[i, j] = acc
            A[j, i] = acc


@nb.njit(cache=True)
def new_work() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scratch of :func:`propagate` (allocated once per kernel call, not per sample):
    vectors (8, 8), matrices (6, 4, 4) and the plant's algebraic work array."""
    return np.zeros((8, 8)), np.zeros((6, N_X + 1, N_X + 1)), np.zeros(apk.N_ALG)


@nb.njit(cache=True)
def propagate(
    x: np.ndarray,
    mem: np.ndarray,
    u0: np.ndarray,
    u1: np.ndarray,
    dt: float,
    n_sub: int,
    prm: np.ndarray,
    q_rate: np.ndarray,
    Phi: np.ndarray,
    Qd: np.ndarray,
    work: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> bool:
    """Advance ``x`` (3,) and ``mem`` (2,) over one sample period ``dt`` [s]; ``Φ ← ∂x⁺/∂x``
    and ``Qd`` ← the process noise accumulated over the period.

    ``n_sub`` exponential-Euler steps of ``h = dt / n_sub``: with ``J_i``, ``f_i`` at
    ``(x_i, u(t_i + h/2))`` (inputs linear between ``u0`` and ``u1``),
    ``exp([[J_i, f_i], [0, 0]] h) = [[E_i, d_i], [0, 1]]``, ``x_{i+1} = x_i + d_i``
    (``d_i = h φ1(h J_i) f_i``, exact for locally affine dynamics), ``Φ ← E_i Φ`` and
    ``Qd ← E_i Qd E_iᵀ + diag(q_rate[:3]) h`` (white process noise of intensity ``q_rate``
    [unit²/s] entering continuously, so a fast, well-damped state such as ``p_im`` is not
    credited with more uncertainty than its dynamics let it hold); the memory takes the
    plant's one fixed-point iteration per step. Returns True if a step left
    the safety box (the state is projected back, see :func:`clamp_to_box`). ``work`` is
    :func:`new_work`.
    """
    vec, mat, alg = work
    u = vec[0, :N_U]
    f = vec[1, :N_X]
    fp = vec[2, :N_X]
    fm = vec[3, :N_X]
    xs = vec[4, :N_X]
    x8 = vec[5]
    dx8 = vec[6]
    J = mat[0, :N_X, :N_X]
    tmp = mat[1, :N_X, :N_X]
    M = mat[2]
    T = mat[3]
    R = mat[4]
    S = mat[5]
    h = dt / n_sub
    for i in range(N_X):
        for j in range(N_X):
            Phi[i, j] = 1.0 if i == j else 0.0
            Qd[i, j] = 0.0
    for i in range(N_X + 1):
        M[N_X, i] = 0.0
    moved = False
    for step in range(n_sub):
        a = (step + 0.5) / n_sub
        for c in range(N_U):
            u[c] = u0[c] + a * (u1[c] - u0[c])
        model_rhs(x, u, mem, prm, x8, dx8, alg, f)
        t1_new = alg[apk.A_T1_NEW]
        xr_new = alg[apk.A_XR_NEW]
        model_jacobian(x, u, mem, prm, x8, dx8, alg, xs, fp, fm, J)
        for i in range(N_X):
            for j in range(N_X):
                M[i, j] = J[i, j] * h
            M[i, N_X] = f[i] * h
        expm_affine(M, T, R, S)
        for i in range(N_X):
            x[i] += R[i, N_X]
        for i in range(N_X):
            for j in range(N_X):
                acc = 0.0
                for c in range(N_X):
                    acc += R[i, c] * Phi[c, j]
                tmp[i, j] = acc
        for i in range(N_X):
            for j in range(N_X):
                Phi[i, j] = tmp[i, j]
        _congruence(R, Qd, tmp)
        for i in range(N_X):
            Qd[i, i] += q_rate[i] * h
        mem[0] = t1_new
        mem[1] = xr_new
        if clamp_to_box(x, prm):
            moved = True
    return moved


@nb.njit(cache=True)
def settle(x: np.ndarray, mem: np.ndarray, u: np.ndarray, seconds: float, prm: np.ndarray) -> None:
    """Run the model ``seconds`` [s] at constant inputs ``u`` (an initial steady state)."""
    Phi = np.empty((N_X, N_X))
    Qd = np.empty((N_X, N_X))
    q_rate = np.zeros(N_X)
    work = new_work()
    n = max(math.ceil(seconds / 0.1), 1)
    for _ in range(n):
        propagate(x, mem, u, u, seconds / n, 20, prm, q_rate, Phi, Qd, work)


@nb.njit(cache=True)
def map_value(theta: np.ndarray, g: np.ndarray, w: float) -> tuple[float, float, int, float]:
    """``q(w, θ)`` interpolated linearly over ``g`` (clamped, docs/algorithms.md §1), its slope
    ``∂q/∂w`` (0 outside the grid), the cell ``i`` and weight ``η``."""
    cell, eta = _locate(g, w)
    t0 = theta[cell]
    t1 = theta[cell + 1]
    q = (1.0 - eta) * t0 + eta * t1
    slope = (t1 - t0) / (g[cell + 1] - g[cell]) if g[0] < w < g[g.shape[0] - 1] else 0.0
    return q, slope, cell, eta


@nb.njit(cache=True)
def output_value(
    j: int,
    x: np.ndarray,
    mode: int,
    g: np.ndarray,
    u: np.ndarray,
    mem: np.ndarray,
    prm: np.ndarray,
    alg: np.ndarray,
) -> float:
    """Model output ``j`` at ``x`` without its Jacobian (see :func:`measurement`)."""
    if j == Y_P_IM:
        return x[0]
    if j == Y_P_EM:
        return x[1]
    if j == Y_OMEGA_T:
        return x[2]
    w = _w_c(x, u, mem, prm, alg)
    if mode == MODE_DEF:
        return w
    if mode == MODE_AUG:
        return w + x[N_X]
    return (1.0 + map_value(x[N_X:], g, w)[0]) * w


@nb.njit(cache=True)
def measurement(
    j: int,
    x: np.ndarray,
    mode: int,
    g: np.ndarray,
    u: np.ndarray,
    mem: np.ndarray,
    prm: np.ndarray,
    alg: np.ndarray,
    xs: np.ndarray,
    grad: np.ndarray,
    H: np.ndarray,
) -> float:
    """Model output ``j`` (``Y_*``) at the full state ``x`` and its Jacobian row ``H``.

    ``Y_MAF``: ``W = W_c(x_s)`` (Def), ``W + b`` (Aug), ``(1 + q(W, θ)) W`` (Map) —
    EKF §5.1 — so ``H_s = (1 + q + W ∂q/∂W) ∂W_c/∂x_s``, ``H_θ = ((1−η) W, η W)`` on the two
    grid values of the cell; ``Y_P_IM``, ``Y_P_EM``, ``Y_OMEGA_T``: the state itself.
    """
    m = x.shape[0]
    for i in range(m):
        H[i] = 0.0
    if j == Y_P_IM:
        H[0] = 1.0
        return x[0]
    if j == Y_P_EM:
        H[1] = 1.0
        return x[1]
    if j == Y_OMEGA_T:
        H[2] = 1.0
        return x[2]
    w = compressor_flow(x, u, mem, prm, alg, xs, grad)
    if mode == MODE_DEF:
        for i in range(N_X):
            H[i] = grad[i]
        return w
    if mode == MODE_AUG:
        for i in range(N_X):
            H[i] = grad[i]
        H[N_X] = 1.0
        return w + x[N_X]
    q, slope, cell, eta = map_value(x[N_X:], g, w)
    gain = 1.0 + q + w * slope
    for i in range(N_X):
        H[i] = gain * grad[i]
    H[N_X + cell] = (1.0 - eta) * w
    H[N_X + cell + 1] = eta * w
    return (1.0 + q) * w


@nb.njit(cache=True)
def ekf_kernel(
    x: np.ndarray,
    P: np.ndarray,
    mem: np.ndarray,
    counts: np.ndarray,
    mode: int,
    g: np.ndarray,
    time: np.ndarray,
    U: np.ndarray,
    Y: np.ndarray,
    use: np.ndarray,
    r_abs2: np.ndarray,
    r_rel2: np.ndarray,
    accept: np.ndarray,
    q_rate: np.ndarray,
    p0_diag: np.ndarray,
    limit: int,
    gate2: float,
    max_step_s: float,
    prm: np.ndarray,
    start: int,
    stop: int,
    x_out: np.ndarray,
    w_c_out: np.ndarray,
    yhat_out: np.ndarray,
    corr_out: np.ndarray,
    status_out: np.ndarray,
    e_out: np.ndarray,
    s_out: np.ndarray,
) -> None:
    """Filter log samples ``start … stop−1``, advancing ``x`` (m,), ``P`` (m, m), ``mem``
    (2,) and ``counts`` in place (whole-log arrays ``time``, ``U`` (n, 4), ``Y`` (n, 4),
    ``accept``; per-sample outputs are written at ``k − start``).

    ``x = [p_im, p_em, ω_t]`` (Def), ``+ [b]`` (Aug, kg/s) or ``+ θ`` (Map, ``len(g)``
    values). ``x``, ``P``, ``mem`` hold the posterior of sample ``start − 1`` (or the prior
    of sample 0 when ``start = 0``). Per sample ``k``:

    1. (``k > 0``) predict from ``k − 1``: :func:`propagate` with
       ``n_sub = ⌈Δt / max_step_s⌉``, ``P ← F P Fᵀ + blockdiag(Qd, diag(q_rate[3:]) Δt)``
       with ``F = blockdiag(Φ, I)`` (parameters are random walks, EKF (4b)); then every
       parameter variance ``P_ii > P0_ii`` is capped (EKF §3.1, docs/algorithms.md §2.5):
       ``limit = LIMIT_PSD`` scales row and column ``i`` by ``√(P0_ii / P_ii)`` (``D P D``,
       ``P`` stays PSD); ``LIMIT_DIAG`` is the paper's literal cap ``P_ii ← min(P_ii, P0_ii)``
       with the off-diagonals left as they are, which can make ``P`` indefinite (the paper
       caps the diagonal and says nothing of the off-diagonal terms; leaving them is the
       literal reading); ``LIMIT_NONE`` caps nothing;
    2. the prior outputs ``ŷ_j`` (all four) go to ``yhat_out``;
    3. unless ``accept[k]`` is false, for each used output ``j`` in order: ``ŷ_j = h_j(x)``,
       ``H_j`` (:func:`measurement`), ``e = Y[k, j] − ŷ_j``, ``v = P H_jᵀ``,
       ``R = r_abs2[j] + r_rel2[j] Y[k, j]²``, ``d = H_j v``, ``s = d + R``; if
       ``e² > gate2 · s`` the output is rejected (χ² gate, 1 dof;
       ``counts[C_GATE + j] += 1``); else ``x ← x + α v e / s``,
       ``P ← P − α(2 − α) v vᵀ / s`` with ``α`` the first of ``1, ½, ¼, …, 2⁻¹²`` that
       decreases the MAP cost ``V(α) = (αe)² d / s² + (y − h_j(x + α v e/s))² / R``
       enough (Armijo, ``V(α) ≤ V(0) + 10⁻⁴ α V'(0)``), else 0 (update dropped); ``α < 1``
       is counted in ``counts[C_DAMPED + j]``. For an output linear over the step ``α = 1``:
       the plain EKF update. The line search is the damped update of the optimisation view
       of the EKF (Skoglund, Hendeby & Axehill 2015); the air path needs it where the
       compressor flow has its kink at ``p_im = p_amb`` (LPV (2) with the plant's
       sub-ambient restriction flow: ``∂W_c/∂p_im`` jumps from ≈ 0 to −10⁻⁴ kg/(s Pa));
    4. the posterior states, ``Ŵ_c = W_c(x̂_s)`` — the estimate of the *true* compressor
       flow — and the MAF correction (``b``, or ``q(Ŵ_c)``; 0 for Def) are written out.

    ``status_out``: 0 all used outputs accepted, 1 sample masked, 2 an output gated. A state
    pushed out of the plant's safety box is projected back and ``counts[C_CLAMP]`` counted.

    ``e_out``, ``s_out`` (``stop − start``, N_Y), unless empty: each scalar update's
    innovation ``e`` and its variance ``s`` of step 3, as its χ² gate tests them (gated or
    not), NaN where the output is not used or the sample masked (docs/tuning.md#innovations:
    the EKF's NIS and likelihood).
    """
    m = x.shape[0]
    H = np.empty(m)
    v = np.empty(m)
    x_try = np.empty(m)
    tmp = np.empty((N_X, m))
    row = np.empty(N_X)
    Phi = np.empty((N_X, N_X))
    Qd = np.empty((N_X, N_X))
    alg = np.empty(apk.N_ALG)
    xs = np.empty(N_X)
    grad = np.empty(N_X)
    work = new_work()
    innovations = e_out.shape[0] > 0
    for k in range(start, stop):
        o = k - start
        clamped = False
        if innovations:
            for j in range(N_Y):
                e_out[o, j] = math.nan
                s_out[o, j] = math.nan
        if k > 0:
            dt = time[k] - time[k - 1]
            n_sub = max(math.ceil(dt / max_step_s - 1e-9), 1)
            if propagate(x, mem, U[k - 1], U[k], dt, n_sub, prm, q_rate, Phi, Qd, work):
                clamped = True
            for i in range(N_X):  # tmp = Φ P[:3, :]
                for c in range(m):
                    acc = 0.0
                    for a in range(N_X):
                        acc += Phi[i, a] * P[a, c]
                    tmp[i, c] = acc
            for i in range(N_X):  # P[:3, :3] = tmp[:, :3] Φᵀ; P[:3, 3:] = tmp[:, 3:]
                for c in range(N_X):
                    acc = 0.0
                    for a in range(N_X):
                        acc += tmp[i, a] * Phi[c, a]
                    row[c] = acc
                for c in range(N_X):
                    P[i, c] = row[c]
                for c in range(N_X, m):
                    P[i, c] = tmp[i, c]
                    P[c, i] = tmp[i, c]
            for i in range(N_X):  # exact symmetry of the state block, plus its noise
                for c in range(i, N_X):
                    mean = 0.5 * (P[i, c] + P[c, i]) + Qd[i, c]
                    P[i, c] = mean
                    P[c, i] = mean
            for i in range(N_X, m):
                P[i, i] += q_rate[i] * dt
            if limit == LIMIT_PSD:
                for i in range(N_X, m):
                    if P[i, i] > p0_diag[i]:
                        _cap_row_col(P, i, p0_diag[i])
            elif limit == LIMIT_DIAG:
                for i in range(N_X, m):
                    if P[i, i] > p0_diag[i]:
                        P[i, i] = p0_diag[i]
        for j in range(N_Y):
            yhat_out[o, j] = output_value(j, x, mode, g, U[k], mem, prm, alg)
        status = ACCEPTED
        if not accept[k]:
            status = REJECTED_MASK
        else:
            for j in range(N_Y):
                if not use[j]:
                    continue
                yhat = measurement(j, x, mode, g, U[k], mem, prm, alg, xs, grad, H)
                for i in range(m):
                    acc = 0.0
                    for c in range(m):
                        if H[c] != 0.0:
                            acc += P[i, c] * H[c]
                    v[i] = acc
                r = r_abs2[j] + r_rel2[j] * Y[k, j] * Y[k, j]
                d = 0.0
                for c in range(m):
                    if H[c] != 0.0:
                        d += H[c] * v[c]
                s = d + r
                e = Y[k, j] - yhat
                if innovations:
                    e_out[o, j] = e
                    s_out[o, j] = s
                if e * e > gate2 * s:
                    counts[C_GATE + j] += 1
                    status = REJECTED_GATE
                    continue
                ge = e / s
                # Line search on V(α) = (αe)² d/s² + (y − h(x + α v e/s))²/R along the Kalman
                # step: α = 1 (the EKF update) unless h is too non-linear over the step.
                v0 = e * e / r
                dv0 = -2.0 * e * e * d / (s * r)
                alpha = 1.0
                for _ in range(MAX_HALVINGS + 1):
                    for i in range(m):
                        x_try[i] = x[i] + alpha * v[i] * ge
                    res = Y[k, j] - output_value(j, x_try, mode, g, U[k], mem, prm, alg)
                    ae = alpha * e
                    cost = ae * ae * d / (s * s) + res * res / r
                    if cost <= v0 + ARMIJO_C * alpha * dv0:
                        break
                    alpha *= 0.5
                else:
                    alpha = 0.0
                if alpha < 1.0:
                    counts[C_DAMPED + j] += 1
                if alpha == 0.0:
                    continue
                for i in range(m):
                    x[i] = x_try[i]
                # covariance of the gain α K: P − α(2 − α) v vᵀ / s (Joseph form, scalar)
                f = alpha * (2.0 - alpha) / s
                for i in range(m):
                    vi = v[i]
                    if vi != 0.0:
                        for c in range(m):
                            P[i, c] -= (vi * v[c]) * f
                if clamp_to_box(x, prm):
                    clamped = True
        if clamped:
            counts[C_CLAMP] += 1
        status_out[o] = status
        for i in range(N_X):
            x_out[o, i] = x[i]
        w_hat = _w_c(x, U[k], mem, prm, alg)
        w_c_out[o] = w_hat
        if mode == MODE_DEF:
            corr_out[o] = 0.0
        elif mode == MODE_AUG:
            corr_out[o] = x[N_X]
        else:
            corr_out[o] = map_value(x[N_X:], g, w_hat)[0]
