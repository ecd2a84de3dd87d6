"""Engine torque estimators of TQ §III and §V: UIO, sliding mode, dirty differentiation and
the two adaptive parameter laws.

Source: Na, Chen, Herrmann, Burke, Brace, *Vehicle engine torque estimation via unknown input
observer and adaptive parameter estimation*, IEEE TVT 2018 ("TQ"); ALGORITHMS.md §5. The
public API is :mod:`estimation.torque`; these kernels only integrate. Each takes whole input
arrays of one chunk, advances its state arrays in place and writes one value per sample into
its ``out`` arrays; no validation, no allocation in the loop.

Units: ``N`` rpm, torques N·m, ``ṁ_ai`` kg/s (scaled to the configured unit inside Φ), time
s, ``J`` N·m·s/rpm (N in rpm).

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
  is advanced exactly like ``P``. ``K`` itself is never formed (next item).
* The sliding-mode observer (TQ (19)) is integrated by explicit Euler at the data rate.
* The parameter laws (TQ (50), (54)) are integrated by implicit (backward) Euler with
  ``P, Q, R, Φ_f`` held over the step: with the paper's ``Γ = diag(0.1, 100)`` the stiffest
  mode ``Γ₁·P₁₁ ≈ 5·10⁴ s⁻¹`` makes explicit Euler diverge at 1 kHz, backward Euler is
  A-stable. The step is solved as ``(S + Ts·A)Θ̂⁺ = S·Θ̂ + Ts·c`` with ``S = G⁻¹`` (``Γ⁻¹``,
  or ``RΓ⁻¹`` for ``G = ΓK``), the same equation as ``(I + Ts·G·A)Θ̂⁺ = Θ̂ + Ts·G·c`` times
  ``S`` but without ``K = R⁻¹``, which grows as ``e^{ℓt}`` along any direction Φ_f leaves
  unexcited (TQ (53) without the PE of TQ Lemma 8).
* Without PE the exact law still moves Θ̂ only along ``K0⁻¹Φ_fᵀ`` (the ``e^{−ℓt}`` cancels
  in ``KΦ_fᵀ``), but in floating point ``e^{−ℓt}K0`` sinks below the round-off of ``P`` after
  ~3.5 s, and round-off then steers Θ̂ (θ̂ ~ 10²⁰ in 60 s of constant data at Γ = 100). The
  kernel therefore uses ``R + R_FLOOR·diag(R)``, ``R_FLOOR = 10⁻⁹`` (10⁷ above round-off),
  capping ``K`` at ``10⁹/diag(R)``. On the torque scenarios this moves ISE by < 0.2 %; on
  constant data Θ̂ stays bounded and ΦΘ̂ on target. A step matrix that is singular or whose
  entries have decayed towards underflow (no data at all for ~35 s) leaves Θ̂ unchanged.
"""

import math

import numba as nb

R_FLOOR = 1e-9
"""Relative floor on ``R = K⁻¹`` (TQ (53)): ``R + R_FLOOR·diag(R)`` keeps ``R`` positive definite
against round-off when Φ_f excites only one direction (see :func:`adaptive_kernel`)."""


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
    air_scale,
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
        S   = G⁻¹ = Γ⁻¹ or R̃Γ⁻¹,  R̃ = R + R_FLOOR·diag(R)
        Θ̂ ← (S + Ts·A)⁻¹ (S·Θ̂ + Ts·c)                       backward Euler of Θ̂' = −G(AΘ̂ − c)
        P, Q, R, N_f, τ_lf, Φ_f ← exact ZOH steps (module docstring)

    State arrays, advanced in place: ``filt`` (4,) = ``[N_f rpm, τ_lf N·m, Φ_f1 rpm,
    Φ_f2 air unit]``; ``P`` (2, 2); ``Q`` (2,); ``R`` (2, 2) = ``K⁻¹`` (unused by the constant
    gain); ``theta`` (2,) = ``Θ̂`` [N·m/rpm, N·m/(air unit)]. ``ṁ_ai`` enters Φ as
    ``air_scale·air_kg_s`` (1 for kg/s, 1000 for g/s, 3600 for kg/h). Inputs and outputs (n,).
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
        m = air_scale * air_kg_s[i]
        y = g * (n - n_f) + t_lf
        out_torque[i] = n * th1 + m * th2
        out_theta1[i] = th1
        out_theta2[i] = th2
        # λ_min = det/λ_max: no cancellation against λ_max ≈ P11 (N² ≫ ṁ_ai²)
        half_df = 0.5 * (p11 - p22)
        lam_max = 0.5 * (p11 + p22) + math.sqrt(half_df * half_df + p12 * p12)
        out_lambda_min[i] = (p11 * p22 - p12 * p12) / lam_max if lam_max > 0.0 else 0.0
        # W1 + κW2 = AΘ̂ − c
        a11 = p11 + kappa * f1 * f1
        a12 = p12 + kappa * f1 * f2
        a22 = p22 + kappa * f2 * f2
        c1 = q1 + kappa * f1 * y
        c2 = q2 + kappa * f2 * y
        # Backward Euler of S·Θ̂' = −(AΘ̂ − c) with S = G⁻¹: Γ⁻¹ (TQ (50)) or RΓ⁻¹ (TQ (54),
        # G = ΓK = ΓR⁻¹), i.e. (S + Ts·A)Θ̂⁺ = S·Θ̂ + Ts·c. Never forms K = R⁻¹, which grows
        # as e^{ℓt} along a direction Φ_f does not excite (TQ (53) without PE).
        if time_varying:
            s11 = r11 * (1.0 + R_FLOOR) / gamma1
            s12 = r12 / gamma2
            s21 = r12 / gamma1
            s22 = r22 * (1.0 + R_FLOOR) / gamma2
        else:
            s11 = 1.0 / gamma1
            s12 = 0.0
            s21 = 0.0
            s22 = 1.0 / gamma2
        m11 = s11 + Ts * a11
        m12 = s12 + Ts * a12
        m21 = s21 + Ts * a12
        m22 = s22 + Ts * a22
        v1 = s11 * th1 + s12 * th2 + Ts * c1
        v2 = s21 * th1 + s22 * th2 + Ts * c2
        det_m = m11 * m22 - m12 * m21
        size = abs(m11 * m22) + abs(m12 * m21)
        if size > 1e-280 and det_m != 0.0 and math.isfinite(det_m):  # else no data: keep Θ̂
            th1, th2 = (m22 * v1 - m12 * v2) / det_m, (m11 * v2 - m21 * v1) / det_m
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
