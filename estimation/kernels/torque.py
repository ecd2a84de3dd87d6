"""Engine torque estimators of TQ §III and §V: UIO, sliding mode, dirty differentiation and
the two adaptive parameter laws.

Source: Na, Chen, Herrmann, Burke, Brace, *Vehicle engine torque estimation via unknown input
observer and adaptive parameter estimation*, IEEE TVT 2018 ("TQ"); ALGORITHMS.md §5. The
public API is :mod:`estimation.torque`; these kernels only integrate. Each takes whole input
arrays of one chunk, advances its state arrays in place and writes one value per sample into
its ``out`` arrays; no validation, no allocation in the loop.

Units: ``N`` rpm, torques N·m, ``ṁ_ai`` kg/s, time s, ``J`` N·m·s/rpm (N in rpm).

Time discretisation (sample period ``Ts``, sample ``i`` at ``t_i``)
-------------------------------------------------------------------
* Every first-order filter ``k ẋ + x = u`` is discretised exactly under a zero-order hold of
  its input: ``x_{i+1} = a·x_i + (1 − a)·u_i`` with ``a = exp(−Ts/k)``. The state arrays hold
  the filter values at ``t_i`` (inputs up to ``i − 1``); the output at sample ``i`` combines
  them with the measurements at ``i``.
* ``Ṗ = −ℓP + Φ_fᵀΦ_f`` and ``Q̇ = −ℓQ + Φ_fᵀy`` (TQ (45)) likewise, exactly under a ZOH of
  their forcing: ``P_{i+1} = b·P_i + (1 − b)/ℓ·Φ_fᵀΦ_f`` with ``b = exp(−ℓ·Ts)``.
* The Riccati equation ``K̇ = ℓK − KΦ_fᵀΦ_fK`` (TQ (52)) is solved through its inverse
  ``R = K⁻¹``, which obeys the linear ``Ṙ = −ℓR + Φ_fᵀΦ_f``, ``R(0) = K0`` (TQ (53)), and so
  is advanced exactly like ``P``; ``K = R⁻¹`` at each sample.
* The sliding-mode observer (TQ (19)) is integrated by explicit Euler at the data rate.
* The parameter laws (TQ (50), (54)) are integrated by implicit (backward) Euler with
  ``P, Q, K, Φ_f`` held over the step: with the paper's ``Γ = diag(0.1, 100)`` the stiffest
  mode ``Γ₁·P₁₁ ≈ 5·10⁴ s⁻¹`` makes explicit Euler diverge at 1 kHz, backward Euler is
  A-stable.
"""

import math

import numba as nb


@nb.njit(cache=True)
def uio_kernel(x, speed_rpm, load_nm, J, k, Ts, out_torque):  # pragma: no cover - compiled
    """UIO, TQ (9), (14): ``k Ṅ_f + N_f = N``, ``k τ̇_lf + τ_lf = τ_l``,
    ``τ̂_e = J (N − N_f)/k + τ_lf``.

    ``x`` (2,) = ``[N_f rpm, τ_lf N·m]`` at the chunk's first sample, advanced in place;
    ``speed_rpm``, ``load_nm``, ``out_torque`` (n,).
    """
    a = math.exp(-Ts / k)
    c = 1.0 - a
    g = J / k
    n_f = x[0]
    t_lf = x[1]
    for i in range(speed_rpm.size):
        n = speed_rpm[i]
        t_l = load_nm[i]
        out_torque[i] = g * (n - n_f) + t_lf
        n_f = a * n_f + c * n
        t_lf = a * t_lf + c * t_l
    x[0] = n_f
    x[1] = t_lf


@nb.njit(cache=True)
def dirty_kernel(x, speed_rpm, load_nm, J, k, Ts, out_torque):  # pragma: no cover - compiled
    """Dirty differentiation, TQ (23)–(24): ``τ̂_e = J N/k − J/(k(ks+1))[N] + τ_l``
    ``= J (N − N_f)/k + τ_l`` with ``k Ṅ_f + N_f = N``.

    ``x`` (1,) = ``[N_f rpm]``, advanced in place; ``speed_rpm``, ``load_nm``, ``out_torque``
    (n,).
    """
    a = math.exp(-Ts / k)
    c = 1.0 - a
    g = J / k
    n_f = x[0]
    for i in range(speed_rpm.size):
        n = speed_rpm[i]
        out_torque[i] = g * (n - n_f) + load_nm[i]
        n_f = a * n_f + c * n
    x[0] = n_f


@nb.njit(cache=True)
def smo_kernel(x, speed_rpm, load_nm, J, k, lambda1, Ts, out_torque):  # pragma: no cover
    """Sliding-mode estimator, TQ (19)–(21): ``J dN̂/dt = −τ_l + λ1 sign(N − N̂)``,
    ``τ̂_e = 1/(ks+1)[λ1 sign(N − N̂)]``.

    ``N̂`` by explicit Euler at the data rate, the low-pass exactly (ZOH); ``x`` (2,) =
    ``[N̂ rpm, τ̂_e N·m]`` at the chunk's first sample, advanced in place. ``sign(0) = 0``.
    """
    a = math.exp(-Ts / k)
    c = 1.0 - a
    h = Ts / J
    n_hat = x[0]
    tau = x[1]
    for i in range(speed_rpm.size):
        e = speed_rpm[i] - n_hat
        v = lambda1 if e > 0.0 else (-lambda1 if e < 0.0 else 0.0)
        out_torque[i] = tau
        n_hat = n_hat + h * (v - load_nm[i])
        tau = a * tau + c * v
    x[0] = n_hat
    x[1] = tau


@nb.njit(cache=True)
def adaptive_kernel(
    filt,
    P,
    Q,
    R,
    theta,
    speed_rpm,
    load_nm,
    air_kg_s,
    J,
    k,
    ell,
    gamma1,
    gamma2,
    kappa,
    time_varying,
    Ts,
    out_torque,
    out_theta1,
    out_theta2,
    out_lambda_min,
):  # pragma: no cover - compiled
    """Adaptive parameter estimation, TQ (41)–(54), ``τ_e = ΦΘ``, ``Φ = [N, ṁ_ai]``.

    Per sample ``i`` (all quantities at ``t_i``)::

        y   = J (N − N_f)/k + τ_lf                            TQ (44) left side + τ_lf
        τ̂_e = Φ Θ̂,   λ_min(P) reported (PE monitor, TQ Remark 9)
        A   = P + κ Φ_fᵀΦ_f,   c = Q + κ Φ_fᵀ y              W1 + κW2 = AΘ̂ − c, TQ (46)–(47)
        G   = Γ            (constant gain, TQ (50))
            = Γ K, K = R⁻¹ (time-varying gain, TQ (52)–(54))
        Θ̂ ← (I + Ts·G·A)⁻¹ (Θ̂ + Ts·G·c)                       backward Euler of Θ̂' = −G(AΘ̂ − c)
        P, Q, R, N_f, τ_lf, Φ_f ← exact ZOH steps (module docstring)

    State arrays, advanced in place: ``filt`` (4,) = ``[N_f rpm, τ_lf N·m, Φ_f1 rpm,
    Φ_f2 kg/s]``; ``P`` (2, 2); ``Q`` (2,); ``R`` (2, 2) = ``K⁻¹`` (unused by the constant
    gain); ``theta`` (2,) = ``Θ̂`` [N·m/rpm, N·m/(kg/s)]. Inputs and outputs (n,).
    """
    a = math.exp(-Ts / k)
    ca = 1.0 - a
    b = math.exp(-ell * Ts)
    cb = (1.0 - b) / ell
    g = J / k
    n_f = filt[0]
    t_lf = filt[1]
    f1 = filt[2]
    f2 = filt[3]
    p11 = P[0, 0]
    p12 = P[0, 1]
    p22 = P[1, 1]
    q1 = Q[0]
    q2 = Q[1]
    r11 = R[0, 0]
    r12 = R[0, 1]
    r22 = R[1, 1]
    th1 = theta[0]
    th2 = theta[1]
    for i in range(speed_rpm.size):
        n = speed_rpm[i]
        m = air_kg_s[i]
        y = g * (n - n_f) + t_lf
        out_torque[i] = n * th1 + m * th2
        out_theta1[i] = th1
        out_theta2[i] = th2
        half_tr = 0.5 * (p11 + p22)
        half_df = 0.5 * (p11 - p22)
        out_lambda_min[i] = half_tr - math.sqrt(half_df * half_df + p12 * p12)
        # W1 + κW2 = AΘ̂ − c
        a11 = p11 + kappa * f1 * f1
        a12 = p12 + kappa * f1 * f2
        a22 = p22 + kappa * f2 * f2
        c1 = q1 + kappa * f1 * y
        c2 = q2 + kappa * f2 * y
        if time_varying:
            det_r = r11 * r22 - r12 * r12
            k11 = r22 / det_r
            k12 = -r12 / det_r
            k22 = r11 / det_r
            g11 = gamma1 * k11
            g12 = gamma1 * k12
            g21 = gamma2 * k12
            g22 = gamma2 * k22
        else:
            g11 = gamma1
            g12 = 0.0
            g21 = 0.0
            g22 = gamma2
        # M = I + Ts·G·A, rhs = Θ̂ + Ts·G·c
        m11 = 1.0 + Ts * (g11 * a11 + g12 * a12)
        m12 = Ts * (g11 * a12 + g12 * a22)
        m21 = Ts * (g21 * a11 + g22 * a12)
        m22 = 1.0 + Ts * (g21 * a12 + g22 * a22)
        s1 = th1 + Ts * (g11 * c1 + g12 * c2)
        s2 = th2 + Ts * (g21 * c1 + g22 * c2)
        det_m = m11 * m22 - m12 * m21
        th1 = (m22 * s1 - m12 * s2) / det_m
        th2 = (m11 * s2 - m21 * s1) / det_m
        # TQ (45), (53): exact ZOH steps of the linear matrix filters
        o11 = cb * f1 * f1
        o12 = cb * f1 * f2
        o22 = cb * f2 * f2
        p11 = b * p11 + o11
        p12 = b * p12 + o12
        p22 = b * p22 + o22
        r11 = b * r11 + o11
        r12 = b * r12 + o12
        r22 = b * r22 + o22
        q1 = b * q1 + cb * f1 * y
        q2 = b * q2 + cb * f2 * y
        # TQ (9), (42): exact ZOH steps of the first-order filters
        n_f = a * n_f + ca * n
        t_lf = a * t_lf + ca * load_nm[i]
        f1 = a * f1 + ca * n
        f2 = a * f2 + ca * m
    filt[0] = n_f
    filt[1] = t_lf
    filt[2] = f1
    filt[3] = f2
    P[0, 0] = p11
    P[0, 1] = p12
    P[1, 0] = p12
    P[1, 1] = p22
    Q[0] = q1
    Q[1] = q2
    R[0, 0] = r11
    R[0, 1] = r12
    R[1, 0] = r12
    R[1, 1] = r22
    theta[0] = th1
    theta[1] = th2
