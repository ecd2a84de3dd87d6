"""Engine torque estimators of TQ §III and §V: UIO, sliding mode, dirty differentiation and
the two adaptive parameter laws.

Source: Na, Chen, Herrmann, Burke, Brace, *Vehicle engine torque estimation via unknown input
observer and adaptive parameter estimation*, IEEE TVT 2018 ("TQ"); docs/algorithms.md §5. The
public API is :mod:`estimation.torque`; these kernels only integrate. Each takes whole input
arrays of one chunk, advances its state arrays in place and writes one value per sample into
its ``out`` arrays; no validation, no allocation in the loop.

Units: ``N`` rpm, torques N·m, ``ṁ_ai`` kg/s (scaled to the configured unit inside Φ), time
s, ``J`` N·m·s/rpm (N in rpm).

Time discretisation (sample period ``Ts``, sample ``i`` at ``t_i``)
-------------------------------------------------------------------
The measurements ``N``, ``τ_l``, ``ṁ_ai`` are held over ``[t_i, t_i + Ts)`` (zero-order hold,
ZOH); every kernel solves the continuous equations of TQ under that hold, exactly where a
closed form exists. State arrays hold values at ``t_i`` (inputs up to ``i − 1``); the output
at sample ``i`` combines them with the measurements at ``i``.

* First-order filters ``k ẋ + x = u``: ``x_{i+1} = a·x_i + (1 − a)·u_i``, ``a = exp(−Ts/k)``,
  exact. The UIO and dirty-differentiation outputs are algebraic in these states and the
  measurements at ``t_i``, so they are the continuous estimators at ``t_i``, exactly.
* Sliding mode (TQ (19)): the switching term ``v = λ1·sign(N_i − N̂_i)`` is sampled and held
  (the continuous sliding mode chatters infinitely fast; at 1 kHz the switch is sampled);
  with ``v`` and ``τ_l`` held ``N̂`` moves linearly, so its explicit Euler step is exact, and
  so is the low-pass of ``v``.
* Adaptive laws. Within a step (``r ∈ [0, Ts]``, ``e(r) = exp(−r/k)``) the filter states are
  affine in ``e``: ``Φ_f(r) = u + d·e(r)``, ``y(r) = y∞ + y_d·e(r)`` with ``u = [N_i, ṁ_i]``,
  ``d = Φ_f(t_i) − u``, ``y∞ = τ_l,i``, ``y_d = J(N_i − N_f(t_i))/k + τ_lf(t_i) − τ_l,i``. The
  forcings of ``Ṗ = −ℓP + Φ_fᵀΦ_f``, ``Q̇ = −ℓQ + Φ_fᵀy`` (TQ (45)) are therefore
  combinations of ``1, e, e²``, and ``P(r) = e^{−ℓr}P_i + I0(r)uuᵀ + I1(r)(udᵀ + duᵀ) +
  I2(r)ddᵀ`` (``Q`` alike) with ``I_j(r) = ∫_0^r e^{−ℓ(r−ρ)}e^{−jρ/k} dρ``: exact. (Holding
  ``Φ_f`` and ``y`` at their ``t_i`` values instead, while they move ~10 % per step at
  ``Ts/k = 0.1``, adds a spurious ``E[Φ_f1·y] = −(J/k)·var(N_f)`` of speed noise, where the
  continuous ``E[N_f·Ṅ_f]`` is 0, and pulls θ̂1 towards ``−J/k``: ISE of (54) κ = 0.1 on
  ``torque-si`` 442–500 instead of 150–160.)
* The Riccati equation ``K̇ = ℓK − KΦ_fᵀΦ_fK`` (TQ (52)) is solved through its inverse
  ``R = K⁻¹``, which obeys the linear ``Ṙ = −ℓR + Φ_fᵀΦ_f``, ``R(0) = K0`` (TQ (53)), and so
  has the same closed form as ``P``. ``K`` itself is never formed (next items).
* ``Θ̂' = −G(t)(A(t)Θ̂ − c(t))`` (TQ (50), (54); ``A = P + κΦ_fᵀΦ_f``, ``c = Q + κΦ_fᵀy``,
  ``G = Γ`` or ``ΓK``) is linear with time-varying coefficients and has no closed form. It
  is integrated by the 2-stage Radau IIA collocation method on :data:`SUBSTEPS` equal steps
  per sample, with ``A``, ``c``, ``R`` evaluated exactly at the nodes ``r = h/3, h`` from the
  closed forms above. Radau IIA is order 3 (global error ``O(h³)``), L-stable and stiffly
  accurate: the stiff mode ``Γ1(P11 + κΦ_f1²) ≈ 10⁵ s⁻¹`` of (50) with the paper's
  ``Γ = diag(0.1, 100)`` (``Ts·λ ≈ 100``) is damped, not amplified, and Θ̂ ends each step on
  its quasi-static value. Substeps are needed because with κ > 0 ``y`` jumps at every sample
  and the stiff mode relaxes from it within ~``Ts/100``; one Radau step leaves
  ``|R(−100)| ≈ 2 %`` of each jump (ISE of (50) κ = 0.1 +1 %), four leave ``10⁻⁵``. Against
  an RK4 integration of the continuous equations (``K`` by its Riccati equation, 100 steps
  per sample) the error falls as ``h³``; with ``SUBSTEPS = 4`` it is ≤ 2·10⁻⁴ N·m after the
  start-up and ≤ 0.13 % while Θ̂(0) = 0 is forgotten, and the scenario ISE is within 0.05 %
  of the converged value. The equation is solved as ``S(t)Θ̂' = −(AΘ̂ − c)`` with
  ``S = G⁻¹`` (``Γ⁻¹``, or ``RΓ⁻¹`` for ``G = ΓK``), by 2×2 block elimination, without
  ``K = R⁻¹``, which grows as ``e^{ℓt}`` along any direction Φ_f leaves unexcited (TQ (53)
  without the PE of TQ Lemma 8).
* Without PE the exact law still moves Θ̂ only along ``K0⁻¹Φ_fᵀ`` (the ``e^{−ℓt}`` cancels
  in ``KΦ_fᵀ``), but in floating point ``e^{−ℓt}K0`` sinks below the round-off of ``P`` after
  ~3.5 s, and round-off then steers Θ̂ (θ̂ ~ 10²⁰ in 60 s of constant data at Γ = 100). The
  kernel therefore uses ``R + R_FLOOR·diag(R)``, ``R_FLOOR = 10⁻⁹`` (10⁷ above round-off),
  capping ``K`` at ``10⁹/diag(R)``. On the torque scenarios this moves ISE by ≤ 0.4 %
  (``torque-si``; < 0.01 % on ``torque-rig``); on constant data Θ̂ stays bounded and ΦΘ̂ on
  target. A step matrix that is singular or whose entries have decayed towards underflow (no
  data at all for ~35 s) leaves Θ̂ unchanged.
"""

import math

import numba as nb

R_FLOOR = 1e-9
"""Relative floor on ``R = K⁻¹`` (TQ (53)): ``R + R_FLOOR·diag(R)`` keeps ``R`` positive definite
against round-off when Φ_f excites only one direction (see :func:`adaptive_kernel`)."""

SUBSTEPS = 4
"""Radau IIA steps per sample of the adaptive laws' Θ̂ equation (module docstring)."""


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
def _decay_integral(ell, rate, r):  # pragma: no cover - compiled
    """``∫_0^r e^{−ℓ(r−ρ)} e^{−rate·ρ} dρ``, also for ``rate`` near ``ℓ`` (expm1 form)."""
    z = (ell - rate) * r
    phi = 1.0 if z == 0.0 else math.expm1(z) / z
    return math.exp(-ell * r) * r * phi


@nb.njit(cache=True)
def _stable_det(m11, m12, m21, m22):  # pragma: no cover - compiled
    """Determinant of a 2×2 matrix, or 0 if it is singular, not finite or underflowing."""
    det = m11 * m22 - m12 * m21
    size = abs(m11 * m22) + abs(m12 * m21)
    if size > 1e-280 and det != 0.0 and math.isfinite(det):
        return det
    return 0.0


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

    Per sample ``i``, inputs ``u = [N_i, ṁ_i]``, ``τ_l,i`` held over ``[t_i, t_i + Ts]``, split
    into SUBSTEPS steps of ``h = Ts/SUBSTEPS``; per step, from its start::

        y   = J (N − N_f)/k + τ_lf                            TQ (44) left side + τ_lf
        τ̂_e = Φ Θ̂,   λ_min(P) reported at t_i (PE monitor, TQ Remark 9)
        on [0, h], e(r) = exp(−r/k):
          Φ_f(r) = u + d·e(r),  y(r) = y∞ + y_d·e(r)           exact ZOH filters
          P(r), Q(r), R(r)                                    closed forms (module doc)
          A = P + κ Φ_fᵀΦ_f,  c = Q + κ Φ_fᵀ y                W1 + κW2 = AΘ̂ − c, TQ (46)–(47)
          S = G⁻¹ = Γ⁻¹ (TQ (50))  or  R̃Γ⁻¹, R̃ = R + R_FLOOR·diag(R) (TQ (52)–(54))
          S·Θ̂' = −(AΘ̂ − c)  by 2-stage Radau IIA, nodes r = h/3, h

    Radau IIA stages ``Z_j = Θ̂(r_j) − Θ̂(0)``, ``W = A_RK⁻¹ = [[3/2, 1/2], [−9/2, 5/2]]``:
    ``Σ_l W_jl S_j Z_l + h·A_j Z_j = h(c_j − A_j Θ̂(0))``, solved by 2×2 block elimination
    (Schur complement on ``Z_2``); ``Θ̂(h) = Θ̂(0) + Z_2`` (stiffly accurate). Singular or
    underflowing blocks (no data for ~35 s under (54)) leave Θ̂ unchanged.

    State arrays, advanced in place: ``filt`` (4,) = ``[N_f rpm, τ_lf N·m, Φ_f1 rpm,
    Φ_f2 air unit]``; ``P`` (2, 2); ``Q`` (2,); ``R`` (2, 2) = ``K⁻¹`` (unused by the constant
    gain); ``theta`` (2,) = ``Θ̂`` [N·m/rpm, N·m/(air unit)]. ``ṁ_ai`` enters Φ as
    ``air_scale·air_kg_s`` (1 for kg/s, 1000 for g/s, 3600 for kg/h). Inputs and outputs (n,).
    """
    g = J / k
    hs = Ts / SUBSTEPS
    # filter decay over the step and to the first Radau node
    a = math.exp(-hs / k)
    e1 = math.exp(-hs / (3.0 * k))
    # P(r) = b(r)·P_i + I0(r)·uuᵀ + I1(r)·(udᵀ + duᵀ) + I2(r)·ddᵀ at r = hs/3 (…1), hs (…2)
    r1 = hs / 3.0
    b1 = math.exp(-ell * r1)
    b2 = math.exp(-ell * hs)
    i01 = _decay_integral(ell, 0.0, r1)
    i11 = _decay_integral(ell, 1.0 / k, r1)
    i21 = _decay_integral(ell, 2.0 / k, r1)
    i02 = _decay_integral(ell, 0.0, hs)
    i12 = _decay_integral(ell, 1.0 / k, hs)
    i22 = _decay_integral(ell, 2.0 / k, hs)
    fl = 1.0 + R_FLOOR
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
        t_l = load_nm[i]
        out_torque[i] = n * th1 + m * th2
        out_theta1[i] = th1
        out_theta2[i] = th2
        # λ_min = det/λ_max: no cancellation against λ_max ≈ P11 (N² ≫ ṁ_ai²)
        half_df = 0.5 * (p11 - p22)
        lam_max = 0.5 * (p11 + p22) + math.sqrt(half_df * half_df + p12 * p12)
        out_lambda_min[i] = (p11 * p22 - p12 * p12) / lam_max if lam_max > 0.0 else 0.0
        for _ in range(SUBSTEPS):  # inputs held: the same ZOH step, SUBSTEPS times
            # Φ_f(r) = u + d·e(r), y(r) = y∞ + y_d·e(r) (TQ (9), (42), (44) under the ZOH)
            d1 = f1 - n
            d2 = f2 - m
            y_inf = t_l
            y_d = g * (n - n_f) + t_lf - t_l
            # forcing integrals: F = Φ_fΦ_fᵀ = uuᵀ + (udᵀ + duᵀ)e + ddᵀe², Φ_f y likewise
            uu11 = n * n
            uu12 = n * m
            uu22 = m * m
            ud11 = 2.0 * n * d1
            ud12 = n * d2 + d1 * m
            ud22 = 2.0 * m * d2
            dd11 = d1 * d1
            dd12 = d1 * d2
            dd22 = d2 * d2
            uy1 = n * y_inf
            uy2 = m * y_inf
            my1 = n * y_d + d1 * y_inf
            my2 = m * y_d + d2 * y_inf
            dy1 = d1 * y_d
            dy2 = d2 * y_d
            o11 = i01 * uu11 + i11 * ud11 + i21 * dd11
            o12 = i01 * uu12 + i11 * ud12 + i21 * dd12
            o22 = i01 * uu22 + i11 * ud22 + i21 * dd22
            # node 1 (r = hs/3): P, Q, Φ_f, y and A, c, S
            h1 = e1 * d1 + n
            h2 = e1 * d2 + m
            yy = e1 * y_d + y_inf
            a11 = b1 * p11 + o11 + kappa * h1 * h1
            a12 = b1 * p12 + o12 + kappa * h1 * h2
            a22 = b1 * p22 + o22 + kappa * h2 * h2
            c1 = b1 * q1 + i01 * uy1 + i11 * my1 + i21 * dy1 + kappa * h1 * yy
            c2 = b1 * q2 + i01 * uy2 + i11 * my2 + i21 * dy2 + kappa * h2 * yy
            if time_varying:  # S = R̃Γ⁻¹: column j divided by γ_j
                s11 = (b1 * r11 + o11) * fl / gamma1
                s12 = (b1 * r12 + o12) / gamma2
                s21 = (b1 * r12 + o12) / gamma1
                s22 = (b1 * r22 + o22) * fl / gamma2
            else:
                s11 = 1.0 / gamma1
                s12 = 0.0
                s21 = 0.0
                s22 = 1.0 / gamma2
            # B11 = 3/2·S1 + hs·A1, B12 = 1/2·S1, rhs1 = hs(c1 − A1Θ̂)
            m11 = 1.5 * s11 + hs * a11
            m12 = 1.5 * s12 + hs * a12
            m21 = 1.5 * s21 + hs * a12
            m22 = 1.5 * s22 + hs * a22
            v1 = hs * (c1 - a11 * th1 - a12 * th2)
            v2 = hs * (c2 - a12 * th1 - a22 * th2)
            det1 = _stable_det(m11, m12, m21, m22)
            # B11⁻¹·S1 (X) and B11⁻¹·rhs1 (x), through the adjugate
            x11 = (m22 * s11 - m12 * s21) / det1 if det1 != 0.0 else 0.0
            x12 = (m22 * s12 - m12 * s22) / det1 if det1 != 0.0 else 0.0
            x21 = (m11 * s21 - m21 * s11) / det1 if det1 != 0.0 else 0.0
            x22 = (m11 * s22 - m21 * s12) / det1 if det1 != 0.0 else 0.0
            w1 = (m22 * v1 - m12 * v2) / det1 if det1 != 0.0 else 0.0
            w2 = (m11 * v2 - m21 * v1) / det1 if det1 != 0.0 else 0.0
            # node 2 (r = hs): the end-of-step values, kept as the new state
            o11 = i02 * uu11 + i12 * ud11 + i22 * dd11
            o12 = i02 * uu12 + i12 * ud12 + i22 * dd12
            o22 = i02 * uu22 + i12 * ud22 + i22 * dd22
            p11 = b2 * p11 + o11
            p12 = b2 * p12 + o12
            p22 = b2 * p22 + o22
            q1 = b2 * q1 + i02 * uy1 + i12 * my1 + i22 * dy1
            q2 = b2 * q2 + i02 * uy2 + i12 * my2 + i22 * dy2
            r11 = b2 * r11 + o11
            r12 = b2 * r12 + o12
            r22 = b2 * r22 + o22
            h1 = a * d1 + n
            h2 = a * d2 + m
            yy = a * y_d + y_inf
            a11 = p11 + kappa * h1 * h1
            a12 = p12 + kappa * h1 * h2
            a22 = p22 + kappa * h2 * h2
            c1 = q1 + kappa * h1 * yy
            c2 = q2 + kappa * h2 * yy
            if time_varying:
                s11 = r11 * fl / gamma1
                s12 = r12 / gamma2
                s21 = r12 / gamma1
                s22 = r22 * fl / gamma2
            # Schur complement: (5/2·S2 + hs·A2 + 9/4·S2·X)·Z2 = hs(c2 − A2Θ̂) + 9/2·S2·x
            m11 = 2.5 * s11 + hs * a11 + 2.25 * (s11 * x11 + s12 * x21)
            m12 = 2.5 * s12 + hs * a12 + 2.25 * (s11 * x12 + s12 * x22)
            m21 = 2.5 * s21 + hs * a12 + 2.25 * (s21 * x11 + s22 * x21)
            m22 = 2.5 * s22 + hs * a22 + 2.25 * (s21 * x12 + s22 * x22)
            v1 = hs * (c1 - a11 * th1 - a12 * th2) + 4.5 * (s11 * w1 + s12 * w2)
            v2 = hs * (c2 - a12 * th1 - a22 * th2) + 4.5 * (s21 * w1 + s22 * w2)
            det2 = _stable_det(m11, m12, m21, m22)
            if det1 != 0.0 and det2 != 0.0:  # else no data: keep Θ̂
                th1 += (m22 * v1 - m12 * v2) / det2
                th2 += (m11 * v2 - m21 * v1) / det2
            # TQ (9), (42): the filters at t_i + hs
            n_f = a * n_f + (1.0 - a) * n
            t_lf = a * t_lf + (1.0 - a) * t_l
            f1 = h1
            f2 = h2
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
