"""Engine torque plants: mean value model with firing ripple, integrated by RK4.

Source: Na et al., *Vehicle engine torque estimation via unknown input observer and adaptive
parameter estimation* (``papers/torque-uio-adaptive-estimation.md``, "TQ"), (1)–(8) and (41).
The public API, parameters and their units are documented in :mod:`estimation.plants.torque`;
this module only integrates. Kernels take a packed coefficient vector ``coef`` (indices below),
write into ``out`` and do no validation and no allocation in the time loop.

Units inside: pressure Pa, temperature K, mass flow kg/s, speed N in rpm, crank angle rad,
torque N·m, time s. ``J`` is the *scaled* inertia of TQ (8) in N·m·s/rpm (``J_kg_m2·2π/60``).

Output row layout (``out[k, OUT_*]``, one row per output sample) is shared by both plants.
"""

import math

import numba as nb
import numpy as np

# --- output columns ---------------------------------------------------------------------
OUT_SPEED_RPM = 0
OUT_SPEED_REF_RPM = 1
OUT_TORQUE_NM = 2  # effective torque τ_e with firing ripple, TQ (7)
OUT_TORQUE_MEAN_NM = 3  # cycle-mean effective torque (MVEM value, no ripple)
OUT_INDICATED_NM = 4  # τ_i with ripple, TQ (5)
OUT_FRICTION_NM = 5  # τ_f, TQ (6)
OUT_LOAD_NM = 6  # τ_l, TQ (8)
OUT_AIR_IN_KG_S = 7  # ṁ_ai, TQ (2)
OUT_AIR_CYL_KG_S = 8  # ṁ_ao, TQ (3)
OUT_FUEL_KG_S = 9  # ṁ_f, TQ (4)
OUT_MANIFOLD_PA = 10  # p_m, TQ (1)
OUT_ACTUATOR = 11  # SI: throttle angle α (deg); rig: filtered torque demand (N·m)
OUT_THETA1 = 12  # θ1 = −τ_f/N, TQ (41)            [N·m/rpm]
OUT_THETA2 = 13  # θ2 = τ_i/ṁ_ai, TQ (41)          [N·m/(kg/s)]
OUT_FIRING_HZ = 14  # firing frequency N·n_cyl/120    [Hz]
N_OUT = 15

# --- coefficients shared by both plants (indices into coef) -------------------------------
C_J = 0  # scaled inertia J                          [N·m·s/rpm]
C_VD = 1  # displacement V_d                          [m³]
C_VM = 2  # intake manifold volume V_m                 [m³]
C_R = 3  # gas constant R                             [J/(kg·K)]
C_KAPPA = 4  # ratio of specific heats κ               [-]
C_TA = 5  # ambient (upstream) temperature T_a         [K]
C_TM = 6  # manifold temperature T_m                   [K]
C_PA = 7  # ambient pressure p_a                        [Pa]
C_EV0 = 8  # η_vol = ev0 + ev1·(N/1000) + ev2·(N/1000)²  [-]
C_EV1 = 9
C_EV2 = 10
C_HU = 11  # fuel lower heating value H_u              [J/kg]
C_ETA_MAX = 12  # η_i = η_max·(1 − c·exp(−N/N_c))        [-]
C_ETA_C = 13
C_ETA_NC = 14  # [rpm]
C_LAMBDA = 15  # air-fuel equivalence ratio λ (SI) / smoke limit λ_min (rig)
C_LTH = 16  # stoichiometric air-fuel ratio L_th        [-]
C_A0 = 17  # friction a0 [N·m], a1 [N·m/rpm], a2 [N·m/rpm²], TQ (6)
C_A1 = 18
C_A2 = 19
C_NCYL = 20  # number of cylinders (4-stroke)
C_R1 = 21  # ripple amplitude of the firing fundamental, relative to mean τ_i
C_R2 = 22  # ripple amplitude of the second firing harmonic
C_KP = 23  # PI proportional gain (SI: deg/rpm; rig: N·m/rpm)
C_KI = 24  # PI integral gain (SI: deg/(rpm·s); rig: N·m/(rpm·s))
# SI plant only
C_MAX = 25  # MAX of TQ (2)                              [kg/s]
C_TC_LEAK = 26  # closed-throttle leakage added to TC(α)   [-]
C_PRI_C = 27  # PRI(p_m) = 1 − exp(c·(p_m/p_a − 1))       [-]
C_ALPHA_MIN = 28  # throttle limits                         [deg]
C_ALPHA_MAX = 29
C_TAU_THR = 30  # throttle actuator time constant         [s]
C_LOAD_C0 = 31  # dyno load τ_l = c0 + c2·(N/1000)²         [N·m]
C_LOAD_C2 = 32  # [N·m/krpm²]
N_SI_COEF = 33
# rig plant only (reuse indices ≥ 25)
C_BOOST_GAIN = 25  # boost target p_a + g·H_u·ṁ_f            [Pa/W]
C_P_MAX = 26  # boost pressure limit                     [Pa]
C_TAU_TURBO = 27  # turbo lag time constant                  [s]
C_TAU_DEMAND = 28  # torque-demand (fuel path) time constant  [s]
C_N_MID = 29  # sweep centre                              [rpm]
C_N_AMP = 30  # sweep amplitude                           [rpm]
C_F0 = 31  # sweep start frequency                     [Hz]
C_F1 = 32  # sweep end frequency                       [Hz]
C_T_SWEEP = 33  # sweep duration                            [s]
N_RIG_COEF = 34

Derivatives = tuple[float, ...]
"""A plant model's return: ``(dp_m, dN, dcrank, dinteg, dx5, N_ref, τ_e, τ_mean, τ_i, τ_f,
τ_l, ṁ_ai, ṁ_ao, ṁ_f)`` (14 floats)."""

TWO_PI = 2.0 * math.pi
RPM_TO_RAD_S = TWO_PI / 60.0


# --- model components (scalars) ---------------------------------------------------------
@nb.njit(cache=True)
def interp_pw(t: float, xs: np.ndarray, ys: np.ndarray) -> float:
    """Piecewise-linear interpolation of ``(xs, ys)`` at ``t``, held constant outside."""
    n = xs.shape[0]
    if t <= xs[0]:
        return ys[0]
    if t >= xs[n - 1]:
        return ys[n - 1]
    i = 0
    while xs[i + 1] < t:
        i += 1
    dx = xs[i + 1] - xs[i]
    if dx <= 0.0:
        return ys[i + 1]
    return ys[i] + (ys[i + 1] - ys[i]) * (t - xs[i]) / dx


@nb.njit(cache=True)
def throttle_flow(alpha_deg: float, p_m: float, coef: np.ndarray) -> float:
    """TQ (2): ``ṁ_ai = MAX·TC(α)·PRI(p_m)`` [kg/s].

    ``TC(α) = 1 − cos α + leak`` and ``PRI = 1 − exp(c·(p_m/p_a − 1))`` (0 for p_m ≥ p_a).
    """
    tc = 1.0 - math.cos(alpha_deg * math.pi / 180.0) + coef[C_TC_LEAK]
    pr = p_m / coef[C_PA]
    pri = 1.0 - math.exp(coef[C_PRI_C] * (pr - 1.0)) if pr < 1.0 else 0.0
    return coef[C_MAX] * tc * pri


@nb.njit(cache=True)
def cylinder_flow(n_rpm: float, p_m: float, coef: np.ndarray) -> float:
    """TQ (3): ``ṁ_ao = √(T_m/T_a)·V_d·η_vol(N)·N·p_m/(120·R·T_m)`` [kg/s]."""
    nk = n_rpm / 1000.0
    eta_vol = coef[C_EV0] + coef[C_EV1] * nk + coef[C_EV2] * nk * nk
    tm = coef[C_TM]
    return (
        math.sqrt(tm / coef[C_TA]) * coef[C_VD] * eta_vol * n_rpm * p_m / (120.0 * coef[C_R] * tm)
    )


@nb.njit(cache=True)
def thermal_efficiency(n_rpm: float, coef: np.ndarray) -> float:
    """η_i(N) = η_max·(1 − c·exp(−N/N_c)) — exponential in N as TQ §II-C states."""
    return coef[C_ETA_MAX] * (1.0 - coef[C_ETA_C] * math.exp(-n_rpm / coef[C_ETA_NC]))


@nb.njit(cache=True)
def indicated_torque_mean(n_rpm: float, m_fuel: float, coef: np.ndarray) -> float:
    """TQ (5): ``τ_i = H_u·η_i·ṁ_f/(2πN/60)`` [N·m] (cycle mean)."""
    return coef[C_HU] * thermal_efficiency(n_rpm, coef) * m_fuel / (n_rpm * RPM_TO_RAD_S)


@nb.njit(cache=True)
def friction_torque(n_rpm: float, coef: np.ndarray) -> float:
    """TQ (6): ``τ_f = a0 + a1·N + a2·N²`` [N·m], N in rpm."""
    return coef[C_A0] + coef[C_A1] * n_rpm + coef[C_A2] * n_rpm * n_rpm


@nb.njit(cache=True)
def ripple_factor(crank_rad: float, coef: np.ndarray) -> float:
    """Firing ripple ``g = 1 + r1·cos ψ + r2·cos 2ψ``, ``ψ = crank·n_cyl/2`` (cycle mean 1).

    A 4-stroke engine fires ``n_cyl/2`` times per crank revolution, so ``ψ`` advances by 2π
    per firing and the fundamental is at ``f = N·n_cyl/120`` Hz.
    """
    psi = crank_rad * coef[C_NCYL] * 0.5
    return 1.0 + coef[C_R1] * math.cos(psi) + coef[C_R2] * math.cos(2.0 * psi)


# --- SI engine with throttle speed controller and road-load dyno --------------------------
@nb.njit(cache=True)
def si_model(
    t: float,
    p_m: float,
    n_rpm: float,
    crank: float,
    integ: float,
    alpha: float,
    coef: np.ndarray,
    ref_time_s: np.ndarray,
    ref_speed_rpm: np.ndarray,
) -> Derivatives:
    """Right-hand side and algebraic outputs of the SI plant at one instant.

    Returns ``(dp_m, dN, dcrank, dinteg, dalpha, N_ref, τ_e, τ_mean, τ_i, τ_f, τ_l, ṁ_ai,
    ṁ_ao, ṁ_f)`` with ``ṁ_f = ṁ_ao/(λ L_th)``, TQ (4).
    """
    n_ref = interp_pw(t, ref_time_s, ref_speed_rpm)
    err = n_ref - n_rpm
    cmd = integ + coef[C_KP] * err
    dinteg = coef[C_KI] * err
    if cmd > coef[C_ALPHA_MAX]:
        cmd = coef[C_ALPHA_MAX]
        if dinteg > 0.0:
            dinteg = 0.0  # anti-windup: stop integrating into the limit
    elif cmd < coef[C_ALPHA_MIN]:
        cmd = coef[C_ALPHA_MIN]
        if dinteg < 0.0:
            dinteg = 0.0
    dalpha = (cmd - alpha) / coef[C_TAU_THR]
    m_ai = throttle_flow(alpha, p_m, coef)
    m_ao = cylinder_flow(n_rpm, p_m, coef)
    dp_m = coef[C_KAPPA] * coef[C_R] / coef[C_VM] * (m_ai * coef[C_TA] - m_ao * coef[C_TM])
    m_f = m_ao / (coef[C_LAMBDA] * coef[C_LTH])
    tau_i_mean = indicated_torque_mean(n_rpm, m_f, coef)
    tau_i = tau_i_mean * ripple_factor(crank, coef)
    tau_f = friction_torque(n_rpm, coef)
    nk = n_rpm / 1000.0
    tau_l = coef[C_LOAD_C0] + coef[C_LOAD_C2] * nk * nk
    tau_e = tau_i - tau_f
    dn = (tau_e - tau_l) / coef[C_J]
    dcrank = n_rpm * RPM_TO_RAD_S
    return (
        dp_m,
        dn,
        dcrank,
        dinteg,
        dalpha,
        n_ref,
        tau_e,
        tau_i_mean - tau_f,
        tau_i,
        tau_f,
        tau_l,
        m_ai,
        m_ao,
        m_f,
    )


@nb.njit(cache=True)
def _write_row(
    row: np.ndarray,
    n_rpm: float,
    n_ref: float,
    tau_e: float,
    tau_mean: float,
    tau_i: float,
    tau_f: float,
    tau_l: float,
    m_ai: float,
    m_ao: float,
    m_f: float,
    p_m: float,
    actuator: float,
    n_cyl: float,
) -> None:
    row[OUT_SPEED_RPM] = n_rpm
    row[OUT_SPEED_REF_RPM] = n_ref
    row[OUT_TORQUE_NM] = tau_e
    row[OUT_TORQUE_MEAN_NM] = tau_mean
    row[OUT_INDICATED_NM] = tau_i
    row[OUT_FRICTION_NM] = tau_f
    row[OUT_LOAD_NM] = tau_l
    row[OUT_AIR_IN_KG_S] = m_ai
    row[OUT_AIR_CYL_KG_S] = m_ao
    row[OUT_FUEL_KG_S] = m_f
    row[OUT_MANIFOLD_PA] = p_m
    row[OUT_ACTUATOR] = actuator
    row[OUT_THETA1] = -tau_f / n_rpm
    row[OUT_THETA2] = tau_i / m_ai
    row[OUT_FIRING_HZ] = n_rpm * n_cyl / 120.0


@nb.njit(cache=True)
def si_manifold_equilibrium_pa(n_rpm: float, alpha_deg: float, coef: np.ndarray) -> float:
    """Manifold pressure with ``ṗ_m = 0`` in TQ (1) at fixed N and α (bisection on p_m)."""
    lo = 0.0
    hi = coef[C_PA]
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        f = (
            throttle_flow(alpha_deg, mid, coef) * coef[C_TA]
            - cylinder_flow(n_rpm, mid, coef) * coef[C_TM]
        )
        if f > 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@nb.njit(cache=True)
def si_steady_torque_nm(n_rpm: float, alpha_deg: float, coef: np.ndarray) -> float:
    """Cycle-mean effective torque τ_e = τ_i − τ_f at the manifold equilibrium (N, α)."""
    p_m = si_manifold_equilibrium_pa(n_rpm, alpha_deg, coef)
    m_f = cylinder_flow(n_rpm, p_m, coef) / (coef[C_LAMBDA] * coef[C_LTH])
    return indicated_torque_mean(n_rpm, m_f, coef) - friction_torque(n_rpm, coef)


# --- diesel test rig: speed-controlled dynamometer, torque-demand engine -------------------
@nb.njit(cache=True)
def rig_speed_ref(t: float, coef: np.ndarray) -> float:
    """Linear-chirp sine sweep ``N_mid + A·sin(2π φ(t))``, ``φ̇`` from f0 to f1 over T_sweep,
    then held at f1."""
    f0 = coef[C_F0]
    f1 = coef[C_F1]
    ts = coef[C_T_SWEEP]
    if t <= ts:
        phase = f0 * t + 0.5 * (f1 - f0) * t * t / ts
    else:
        phase = f0 * ts + 0.5 * (f1 - f0) * ts + f1 * (t - ts)
    return coef[C_N_MID] + coef[C_N_AMP] * math.sin(TWO_PI * phase)


@nb.njit(cache=True)
def rig_fuel(n_rpm: float, demand_nm: float, p_m: float, coef: np.ndarray) -> float:
    """Injected fuel ``ṁ_f`` [kg/s]: TQ (5) inverted for ``τ_i = demand + τ_f(N)``, limited by
    the smoke limit ``ṁ_f ≤ ṁ_ao/(λ_min·L_th)`` (TQ (4) with λ = λ_min) and by 0."""
    tau_i_req = demand_nm + friction_torque(n_rpm, coef)
    m_f = tau_i_req * n_rpm * RPM_TO_RAD_S / (coef[C_HU] * thermal_efficiency(n_rpm, coef))
    smoke = cylinder_flow(n_rpm, p_m, coef) / (coef[C_LAMBDA] * coef[C_LTH])
    if m_f > smoke:
        m_f = smoke
    if m_f < 0.0:
        m_f = 0.0
    return m_f


@nb.njit(cache=True)
def rig_boost_target_pa(m_f: float, coef: np.ndarray) -> float:
    """Boost pressure the turbocharger settles to: ``p_a + g·H_u·ṁ_f``, capped at p_max."""
    p = coef[C_PA] + coef[C_BOOST_GAIN] * coef[C_HU] * m_f
    return min(p, coef[C_P_MAX])


@nb.njit(cache=True)
def rig_model(
    t: float,
    p_m: float,
    n_rpm: float,
    crank: float,
    integ: float,
    demand_f: float,
    coef: np.ndarray,
    demand_time_s: np.ndarray,
    demand_nm: np.ndarray,
) -> Derivatives:
    """Right-hand side and outputs of the diesel rig at one instant.

    Returns ``(dp_m, dN, dcrank, dinteg, ddemand, N_ref, τ_e, τ_mean, τ_i, τ_f, τ_l, ṁ_ai,
    ṁ_ao, ṁ_f)``. The dyno holds speed: ``τ_l = Kp·(N − N_ref) + ∫Ki·(N − N_ref)``.
    ``ṁ_ai`` (compressor/MAF flow) follows from TQ (1) solved for it:
    ``ṁ_ai = (V_m/(κR)·ṗ_m + ṁ_ao·T_m)/T_a``.
    """
    n_ref = rig_speed_ref(t, coef)
    err = n_rpm - n_ref
    tau_l = coef[C_KP] * err + integ
    dinteg = coef[C_KI] * err
    ddemand = (interp_pw(t, demand_time_s, demand_nm) - demand_f) / coef[C_TAU_DEMAND]
    m_f = rig_fuel(n_rpm, demand_f, p_m, coef)
    dp_m = (rig_boost_target_pa(m_f, coef) - p_m) / coef[C_TAU_TURBO]
    m_ao = cylinder_flow(n_rpm, p_m, coef)
    m_ai = (coef[C_VM] / (coef[C_KAPPA] * coef[C_R]) * dp_m + m_ao * coef[C_TM]) / coef[C_TA]
    tau_i_mean = indicated_torque_mean(n_rpm, m_f, coef)
    tau_i = tau_i_mean * ripple_factor(crank, coef)
    tau_f = friction_torque(n_rpm, coef)
    tau_e = tau_i - tau_f
    dn = (tau_e - tau_l) / coef[C_J]
    return (
        dp_m,
        dn,
        n_rpm * RPM_TO_RAD_S,
        dinteg,
        ddemand,
        n_ref,
        tau_e,
        tau_i_mean - tau_f,
        tau_i,
        tau_f,
        tau_l,
        m_ai,
        m_ao,
        m_f,
    )


@nb.njit(cache=True)
def rig_boost_equilibrium_pa(n_rpm: float, demand_nm: float, coef: np.ndarray) -> float:
    """Lowest fixed point of ``p = boost_target(ṁ_f(N, demand, p))`` (iterated from p_a)."""
    p = coef[C_PA]
    for _ in range(500):
        p = rig_boost_target_pa(rig_fuel(n_rpm, demand_nm, p, coef), coef)
    return p


# --- both plants: one RK4 integrator -------------------------------------------------------
PLANT_SI = 0  # si_model; x0 = [p_m (Pa), N (rpm), crank (rad), PI integral (deg), α (deg)]
PLANT_RIG = 1  # rig_model; x0 = [p_m (Pa), N (rpm), crank (rad), dyno PI (N·m), demand (N·m)]


@nb.njit(cache=True)
def plant_model(
    plant: int,
    t: float,
    p_m: float,
    n_rpm: float,
    crank: float,
    integ: float,
    x5: float,
    coef: np.ndarray,
    table_x: np.ndarray,
    table_y: np.ndarray,
) -> Derivatives:
    """:func:`si_model` (``PLANT_SI``) or :func:`rig_model` (``PLANT_RIG``): the 5 state
    derivatives followed by ``(N_ref, τ_e, τ_mean, τ_i, τ_f, τ_l, ṁ_ai, ṁ_ao, ṁ_f)``.

    A branch on an integer rather than the model passed as a function: numba cannot cache a
    kernel that takes (or closes over) a compiled function as a value.
    """
    if plant == PLANT_RIG:
        return rig_model(t, p_m, n_rpm, crank, integ, x5, coef, table_x, table_y)
    return si_model(t, p_m, n_rpm, crank, integ, x5, coef, table_x, table_y)


@nb.njit(cache=True)
def _stage(
    plant: int,
    t: float,
    p_m: float,
    n_rpm: float,
    crank: float,
    integ: float,
    x5: float,
    h: float,
    k: Derivatives,
    coef: np.ndarray,
    table_x: np.ndarray,
    table_y: np.ndarray,
) -> Derivatives:
    """One RK4 stage: :func:`plant_model` at time ``t`` and state ``x + h·k[:5]``."""
    return plant_model(
        plant,
        t,
        p_m + h * k[0],
        n_rpm + h * k[1],
        crank + h * k[2],
        integ + h * k[3],
        x5 + h * k[4],
        coef,
        table_x,
        table_y,
    )


@nb.njit(cache=True)
def torque_rk4_kernel(
    plant: int,
    coef: np.ndarray,
    table_x: np.ndarray,
    table_y: np.ndarray,
    x0: np.ndarray,
    dt_s: float,
    decimation: int,
    out: np.ndarray,
) -> None:
    """Integrate ``plant`` (``PLANT_SI`` or ``PLANT_RIG``) with classical RK4 at step ``dt_s``;
    fill ``out[k]`` every ``decimation`` steps (``out`` has ``n_out`` rows, time
    ``k·decimation·dt_s``).

    ``(table_x, table_y)`` is the SI speed reference (s, rpm) or the rig torque demand
    (s, N·m); ``x0 = [p_m (Pa), N (rpm), crank (rad), PI integral, x5]`` with ``x5`` the
    throttle α (deg, SI) or the filtered demand (N·m, rig), written to ``OUT_ACTUATOR``.
    """
    p = x0[0]
    n = x0[1]
    c = x0[2]
    q = x0[3]
    a = x0[4]
    n_out = out.shape[0]
    h = dt_s
    cycle = 4.0 * math.pi
    for k in range(n_out):
        for j in range(decimation):
            t = (k * decimation + j) * h
            k1 = plant_model(plant, t, p, n, c, q, a, coef, table_x, table_y)
            if j == 0:
                _write_row(
                    out[k],
                    n,
                    k1[5],
                    k1[6],
                    k1[7],
                    k1[8],
                    k1[9],
                    k1[10],
                    k1[11],
                    k1[12],
                    k1[13],
                    p,
                    a,
                    coef[C_NCYL],
                )
                if k == n_out - 1:
                    break
            hh = 0.5 * h
            k2 = _stage(plant, t + hh, p, n, c, q, a, hh, k1, coef, table_x, table_y)
            k3 = _stage(plant, t + hh, p, n, c, q, a, hh, k2, coef, table_x, table_y)
            k4 = _stage(plant, t + h, p, n, c, q, a, h, k3, coef, table_x, table_y)
            w = h / 6.0
            p += w * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            n += w * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            c += w * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
            q += w * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
            a += w * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
            if c >= cycle:
                c -= cycle  # one 720° cycle; keeps the phase exact over long runs
