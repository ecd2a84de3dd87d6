"""Diesel air path with EGR and VGT: the Wahlström & Eriksson (2011) mean value model.

Kernels only (no validation, no allocation inside the time loop); the public API is
:mod:`estimation.plants.airpath`. Notation and equations follow

    J. Wahlström, L. Eriksson, "Modelling diesel engines with a variable-geometry
    turbocharger and exhaust gas recirculation by optimization of model parameters for
    capturing non-linear system dynamics", Proc. IMechE Part D 225 (2011) 960–986 (W&E),

restated as LPV (1)–(3) in the LPV paper. Equation numbers below are LPV numbers where the
LPV paper shows the equation and W&E section names otherwise (the W&E text itself is not in
``/work/shared``; the sub-models are reproduced from the published model and checked against
the parameter file, see the notes at each function).

Units: SI throughout (Pa, K, kg/s, rad/s, W, m, m², m³); engine speed ``n_e`` in rpm, fuel
``u_δ`` in mg/cycle per cylinder, actuator positions in % (0 % EGR = closed, 0 % VGT = closed).

State vector ``x`` (8): ``p_im, p_em, ω_t, X_Oim, X_Oem, ũ_egr1, ũ_egr2, ũ_vgt``;
memory ``mem`` (2): residual-gas temperature ``T_1`` and residual gas fraction ``x_r`` of the
Seiliger cycle, updated once per step by one fixed-point iteration (as W&E do).
"""

import math

import numba as nb
import numpy as np

# ---------------------------------------------------------------------------------------
# Parameter vector layout (built by ``AirpathParams.to_vector``; names in PARAM_NAMES).
PARAM_NAMES = (
    "R_a",
    "R_e",
    "c_pa",
    "c_pe",
    "c_va",
    "gamma_a",
    "gamma_e",
    "T_amb",
    "p_amb",
    "T_im",
    "V_im",
    "V_em",
    "r_c",
    "V_d",
    "n_cyl",
    "q_HV",
    "AFs",
    "X_Oc",
    "hA_pipe",
    "c_vol1",
    "c_vol2",
    "c_vol3",
    "eta_sc",
    "x_cv",
    "R_c",
    "c_wpsi1",
    "c_wpsi2",
    "c_wpsi3",
    "c_wphi1",
    "c_wphi2",
    "c_wphi3",
    "c_psi2",
    "c_phi2",
    "Q_c11",
    "Q_c12",
    "Q_c22",
    "eta_cmax",
    "W_copt",
    "pi_copt",
    "c_pi",
    "A_egrmax",
    "PI_egropt",
    "c_egr1",
    "c_egr2",
    "c_egr3",
    "tau_egr1",
    "tau_egr2",
    "K_egr",
    "tau_degr",
    "A_vgtmax",
    "R_t",
    "BSR_opt",
    "c_m1",
    "c_m2",
    "c_m3",
    "w_tlin",
    "c_mlin",
    "K_t",
    "c_f1",
    "c_f2",
    "c_vgt1",
    "c_vgt2",
    "eta_tmmax",
    "tau_vgt",
    "tau_dvgt",
    "J_t",
    "eta_min",
    "z_lin",
    "omega_t_min",
    "omega_t_max",
    "A_cr",
    "dp_lin",
)
(
    R_A,
    R_E,
    C_PA,
    C_PE,
    C_VA,
    GAMMA_A,
    GAMMA_E,
    T_AMB,
    P_AMB,
    T_IM,
    V_IM,
    V_EM,
    R_COMP,
    V_D,
    N_CYL,
    Q_HV,
    AFS,
    X_OC,
    HA_PIPE,
    C_VOL1,
    C_VOL2,
    C_VOL3,
    ETA_SC,
    X_CV,
    R_C,
    C_WPSI1,
    C_WPSI2,
    C_WPSI3,
    C_WPHI1,
    C_WPHI2,
    C_WPHI3,
    C_PSI2,
    C_PHI2,
    Q_C11,
    Q_C12,
    Q_C22,
    ETA_CMAX,
    W_COPT,
    PI_COPT,
    C_PI,
    A_EGRMAX,
    PI_EGROPT,
    C_EGR1,
    C_EGR2,
    C_EGR3,
    TAU_EGR1,
    TAU_EGR2,
    K_EGR,
    TAU_DEGR,
    A_VGTMAX,
    R_T,
    BSR_OPT,
    C_M1,
    C_M2,
    C_M3,
    W_TLIN,
    C_MLIN,
    K_T,
    C_F1,
    C_F2,
    C_VGT1,
    C_VGT2,
    ETA_TMMAX,
    TAU_VGT,
    TAU_DVGT,
    J_T,
    ETA_MIN,
    Z_LIN,
    OMEGA_T_MIN,
    OMEGA_T_MAX,
    A_CR,
    DP_LIN,
) = range(len(PARAM_NAMES))
N_PARAMS = len(PARAM_NAMES)

# Controller parameter vector layout (built by ``ActuatorSchedule.to_vector``).
CTRL_NAMES = (
    "fuel_full",
    "egr_max_pct",
    "egr_fuel_off",
    "egr_speed_off",
    "egr_speed_band",
    "vgt_min_pct",
    "vgt_max_pct",
    "vgt_ff_closed_pct",
    "boost_max_pa",
    "boost_speed_lo",
    "boost_speed_hi",
    "kp_pct_per_pa",
    "ki_pct_per_pa_s",
    "omega_guard",
    "k_omega_pct",
    "lambda_min",
    "p_em_max",
    "k_pem_pct",
)
(
    FUEL_FULL,
    EGR_MAX,
    EGR_FUEL_OFF,
    EGR_SPEED_OFF,
    EGR_SPEED_BAND,
    VGT_MIN,
    VGT_MAX,
    VGT_FF_CLOSED,
    BOOST_MAX,
    BOOST_N_LO,
    BOOST_N_HI,
    KP,
    KI,
    OMEGA_GUARD,
    K_OMEGA,
    LAMBDA_MIN,
    P_EM_MAX,
    K_PEM,
) = range(len(CTRL_NAMES))
N_CTRL = len(CTRL_NAMES)

# Columns of the per-sample output array.
OUT_NAMES = (
    "p_im",
    "p_em",
    "omega_t",
    "x_o_im",
    "x_o_em",
    "u_egr_pos",
    "u_vgt_pos",
    "u_egr_cmd",
    "u_vgt_cmd",
    "w_c",
    "w_egr",
    "w_ei",
    "w_f",
    "w_t",
    "t_em",
    "t_e",
    "p_c",
    "p_t_eta_m",
    "eta_c",
    "eta_tm",
    "eta_vol",
    "fuel",
    "speed",
    "dp_im",
    "dp_em",
    "domega_t",
    "rho1",
    "rho2",
    "rho3",
    "rho4",
    "rho5",
    "p_im_ref",
    "lambda_o",
    "egr_fraction",
    "bsr",
    "fuel_demand",
)
(
    O_P_IM,
    O_P_EM,
    O_OMEGA_T,
    O_XO_IM,
    O_XO_EM,
    O_U_EGR,
    O_U_VGT,
    O_U_EGR_CMD,
    O_U_VGT_CMD,
    O_W_C,
    O_W_EGR,
    O_W_EI,
    O_W_F,
    O_W_T,
    O_T_EM,
    O_T_E,
    O_P_C,
    O_P_T,
    O_ETA_C,
    O_ETA_TM,
    O_ETA_VOL,
    O_FUEL,
    O_SPEED,
    O_DP_IM,
    O_DP_EM,
    O_DOMEGA_T,
    O_RHO1,
    O_RHO2,
    O_RHO3,
    O_RHO4,
    O_RHO5,
    O_P_IM_REF,
    O_LAMBDA,
    O_EGR_FRAC,
    O_BSR,
    O_FUEL_DEMAND,
) = range(len(OUT_NAMES))
N_OUT = len(OUT_NAMES)

# Columns of the algebraic work array ``alg``.
(
    A_W_C,
    A_W_EGR,
    A_W_EI,
    A_W_F,
    A_W_T,
    A_T_EM,
    A_T_E,
    A_P_C,
    A_P_T,
    A_ETA_C,
    A_ETA_TM,
    A_ETA_VOL,
    A_PHI_C,
    A_PSI_EGR,
    A_F_EGR,
    A_F_PIT,
    A_F_VGT,
    A_T1_NEW,
    A_XR_NEW,
    A_LAMBDA,
    A_BSR,
) = range(21)
N_ALG = 21

# Diagnostic counters.
D_CLAMPS = 0
N_DIAG = 1


@nb.njit(cache=True)
def f_egr(u_egr_pct: float, prm: np.ndarray) -> float:
    """EGR valve area fraction ``f_egr(ũ_egr)`` (W&E, EGR valve model).

    ``c_egr1 ũ² + c_egr2 ũ + c_egr3`` up to the vertex ``ũ = −c_egr2/(2 c_egr1)`` and the
    vertex value ``c_egr3 − c_egr2²/(4 c_egr1)`` beyond it; clipped at 0 for ``ũ < 0``
    (the actuator overshoot model can drive ``ũ`` slightly negative).
    """
    c1 = prm[C_EGR1]
    c2 = prm[C_EGR2]
    c3 = prm[C_EGR3]
    u_top = -c2 / (2.0 * c1)
    if u_egr_pct > u_top:
        f = c3 - c2 * c2 / (4.0 * c1)
    else:
        f = c1 * u_egr_pct * u_egr_pct + c2 * u_egr_pct + c3
    return max(f, 0.0)


@nb.njit(cache=True)
def f_vgt(u_vgt_pct: float, prm: np.ndarray) -> float:
    """VGT effective area fraction (W&E, turbine flow model).

    ``f_vgt = c_f2 + c_f1 sqrt(max(0, 1 − ((ũ_vgt − c_vgt2)/c_vgt1)²))``, floored at 1 % so
    the turbine never closes completely (the fit is negative below ``ũ_vgt ≈ 2 %``; W&E's
    valid range is 20–100 %).
    """
    r = (u_vgt_pct - prm[C_VGT2]) / prm[C_VGT1]
    f = prm[C_F2] + prm[C_F1] * math.sqrt(max(0.0, 1.0 - r * r))
    return max(f, 0.01)


@nb.njit(cache=True)
def turbine_efficiency(bsr: float, c_m: float, eta_max: float, bsr_opt: float) -> float:
    """``η_tm(BSR)``: W&E's parabola ``η_tmmax − c_m (BSR − BSR_opt)²`` near the optimum.

    The parabola reaches 0 at ``BSR ≈ 0.2``, which would give a turbine with zero torque
    at low blade speed — a spurious trap (the turbo can never spool up from rest). Below
    the tangent point ``b_t = √(BSR_opt² − η_tmmax/c_m)`` we use the tangent through the
    origin, ``η = −2 c_m (b_t − BSR_opt) · BSR`` (C¹; finite stall torque, as real turbines
    have). Our addition; identical to W&E for ``BSR ≥ b_t`` (≈ 0.61 with the Scania values).
    """
    d2 = bsr_opt * bsr_opt - eta_max / c_m
    if d2 > 0.0:
        b_t = math.sqrt(d2)
        if bsr < b_t:
            return max(-2.0 * c_m * (b_t - bsr_opt) * bsr, 0.0)
    d = bsr - bsr_opt
    return min(max(eta_max - c_m * d * d, 0.0), eta_max)


@nb.njit(cache=True)
def exhaust_iterate(
    p_im: float, p_em: float, fuel: float, speed: float, T1: float, xr: float, prm: np.ndarray
) -> tuple[float, float, float, float, float, float, float]:
    """The cylinder flows and one Seiliger fixed-point iteration of :func:`airpath_algebra`
    (its equations there): ``(η_vol, W_ei, W_f, W_eo, T_e, T_1 new, x_r new)`` from the
    previous iterate ``(T_1, x_r)``. Apart so that :func:`airpath_rho_kernel` iterates only
    this and evaluates the other sub-models once, at the last iterate."""
    ga = prm[GAMMA_A]
    # --- cylinder
    eta_vol = prm[C_VOL1] * math.sqrt(p_im) + prm[C_VOL2] * math.sqrt(speed) + prm[C_VOL3]
    w_ei = eta_vol * p_im * speed * prm[V_D] / (120.0 * prm[R_A] * prm[T_IM])
    w_f = 1e-6 / 120.0 * prm[N_CYL] * speed * fuel
    w_eo = w_ei + w_f
    # --- exhaust temperature (one fixed-point iteration in (T_1, x_r))
    rc = prm[R_COMP]
    rc_g = rc ** (ga - 1.0)
    pi_e = p_em / p_im
    q_in = w_f * prm[Q_HV] * (1.0 - xr) / w_eo if w_eo > 1e-9 else 0.0
    x_cv = prm[X_CV]
    x_p = 1.0 + q_in * x_cv / (prm[C_VA] * T1 * rc_g)
    x_v = 1.0 + q_in * (1.0 - x_cv) / (prm[C_PA] * (q_in * x_cv / prm[C_VA] + T1 * rc_g))
    pi_e_g = pi_e ** (1.0 / ga)  # Π_e^(1/γa); Π_e^(1−1/γa) = Π_e / Π_e^(1/γa)
    x_p_g = x_p ** (-1.0 / ga)  # x_p^(−1/γa); x_p^(1/γa−1) = 1 / (x_p · x_p^(−1/γa))
    xr_new = pi_e_g * x_p_g / (rc * x_v)
    t_e = (
        prm[ETA_SC]
        * (pi_e / pi_e_g)
        / rc_g
        / (x_p * x_p_g)
        * (q_in * ((1.0 - x_cv) / prm[C_PA] + x_cv / prm[C_VA]) + T1 * rc_g)
    )
    t1_new = xr_new * t_e + (1.0 - xr_new) * prm[T_IM]
    return eta_vol, w_ei, w_f, w_eo, t_e, t1_new, xr_new


@nb.njit(cache=True)
def airpath_algebra(
    p_im: float,
    p_em: float,
    omega_t: float,
    u_egr_pos: float,
    u_vgt_pos: float,
    fuel: float,
    speed: float,
    T1: float,
    xr: float,
    prm: np.ndarray,
    alg: np.ndarray,
) -> None:
    """All algebraic sub-models at one operating point; writes ``alg`` (see ``A_*``).

    Cylinder (LPV (2)):  ``W_ei = η_vol p_im n_e V_d / (120 R_a T_im)``,
    ``η_vol = c_vol1 √p_im + c_vol2 √n_e + c_vol3``; ``W_f = 10⁻⁶/120 · n_cyl n_e u_δ``.

    Exhaust temperature (W&E, Seiliger-cycle model with pipe heat loss):
    ``q_in = W_f q_HV (1 − x_r) / W_eo``, ``x_p = 1 + q_in x_cv / (c_va T_1 r_c^(γa−1))``,
    ``x_v = 1 + q_in (1 − x_cv) / (c_pa (q_in x_cv / c_va + T_1 r_c^(γa−1)))``,
    ``x_r = Π_e^(1/γa) x_p^(−1/γa) / (r_c x_v)``, ``Π_e = p_em/p_im``,
    ``T_e = η_sc Π_e^(1−1/γa) r_c^(1−γa) x_p^(1/γa−1) (q_in((1−x_cv)/c_pa + x_cv/c_va)
    + T_1 r_c^(γa−1))``, ``T_1 = x_r T_e + (1 − x_r) T_im``,
    ``T_em = T_amb + (T_e − T_amb) exp(−h_tot π d_pipe l_pipe n_pipe / (W_eo c_pe))``.
    ``(T_1, x_r)`` in are the previous iterate; the new iterate is written to ``alg``.

    EGR valve (LPV (2)): ``W_egr = A_egrmax f_egr(ũ_egr) Ψ_egr p_em / √(T_em R_e)``,
    ``Ψ_egr = 1 − ((1 − Π_egr)/(1 − Π_egropt) − 1)²``, ``Π_egr = p_im/p_em`` clipped to
    ``[Π_egropt, 1]`` (no reverse flow).

    Turbine (LPV (2)): ``W_t = A_vgtmax f_Πt f_vgt(ũ_vgt) p_em / √(T_em R_e)``,
    ``f_Πt = √(1 − Π_t^K_t)``, ``Π_t = p_amb/p_em``; for ``z = 1 − Π_t^K_t < z_lin`` the
    square root is replaced by the C¹ quadratic ``z (3 z_lin − z) / (2 z_lin^(3/2))`` (finite
    slope at ``Π_t = 1``: keeps the explicit integration stable; our addition), 0 for ``z ≤ 0``.
    ``P_t η_m = η_tm W_t c_pe T_em (1 − Π_t^(1−1/γe))``, ``η_tm = η_tmmax − c_m (BSR −
    BSR_opt)²``, ``BSR = R_t ω_t / √(2 c_pe T_em (1 − Π_t^(1−1/γe)))``,
    ``c_m = c_m1 (ω_t − c_m2)^c_m3`` for ``ω_t > ω_tlin`` else ``c_mlin`` (continuous: the
    parameter file's ``c_m1 (ω_tlin − c_m2)^c_m3 = c_mlin``); below the BSR where the tangent
    from the origin touches the parabola, ``η_tm`` follows that tangent (see
    :func:`turbine_efficiency`).

    Compressor (LPV (2)): ``W_c = p_amb π R_c³ ω_t Φ_c / (R_a T_amb)``,
    ``Φ_c = √(max(0, (1 − c_Ψ1 (Ψ_c − c_Ψ2)²) / c_Φ1)) + c_Φ2``,
    ``Ψ_c = 2 c_pa T_amb (Π_c^(1−1/γa) − 1) / (R_c² ω_t²)``, ``Π_c = p_im/p_amb``,
    ``c_Ψ1 = c_wΨ1 ω_t² + c_wΨ2 ω_t + c_wΨ3``, ``c_Φ1 = c_wΦ1 ω_t² + c_wΦ2 ω_t + c_wΦ3``;
    ``Ψ_c`` is floored at ``c_Ψ2`` (below ambient the fit would shut the flow; we hold the
    zero-head flow instead — our addition), and below ambient a parallel restriction flow
    ``A_cr √(2 ρ_amb (p_amb − p_im))`` is added (ours; C¹-regularised below ``dp_lin``) so a
    slow turbo cannot starve the engine; ``Φ_c`` is then the effective value
    ``W_c R_a T_amb / (p_amb π R_c³ ω_t)`` so ``ρ1 ω_t = W_c`` still holds.
    ``η_c = η_cmax − χᵀ Q_c χ``,
    ``χ = (W_c − W_copt, (Π_c − 1)^c_pi − π_copt)``, clipped to ``[η_min, η_cmax]``;
    ``P_c = W_c c_pa T_amb max(Π_c^(1−1/γa) − 1, 0) / η_c``.
    """
    ga = prm[GAMMA_A]
    ge = prm[GAMMA_E]
    eta_vol, w_ei, w_f, w_eo, t_e, t1_new, xr_new = exhaust_iterate(
        p_im, p_em, fuel, speed, T1, xr, prm
    )
    t_amb = prm[T_AMB]
    if w_eo > 1e-9:
        t_em = t_amb + (t_e - t_amb) * math.exp(-prm[HA_PIPE] / (w_eo * prm[C_PE]))
    else:
        t_em = t_amb
    sq_te = math.sqrt(t_em * prm[R_E])
    # --- EGR valve
    pi_egr = p_im / p_em
    pi_opt = prm[PI_EGROPT]
    pi_egr = min(max(pi_egr, pi_opt), 1.0)
    r = (1.0 - pi_egr) / (1.0 - pi_opt) - 1.0
    psi_egr = 1.0 - r * r
    fe = f_egr(u_egr_pos, prm)
    w_egr = prm[A_EGRMAX] * fe * psi_egr * p_em / sq_te
    # --- turbine
    pi_t = prm[P_AMB] / p_em
    z = 1.0 - pi_t ** prm[K_T]
    zl = prm[Z_LIN]
    if z <= 0.0:
        f_pit = 0.0
    elif z < zl:
        f_pit = z * (3.0 * zl - z) / (2.0 * zl * math.sqrt(zl))
    else:
        f_pit = math.sqrt(z)
    fv = f_vgt(u_vgt_pos, prm)
    w_t = prm[A_VGTMAX] * f_pit * fv * p_em / sq_te
    dh_t = prm[C_PE] * t_em * max(1.0 - pi_t ** (1.0 - 1.0 / ge), 0.0)
    bsr = prm[R_T] * omega_t / math.sqrt(2.0 * dh_t) if dh_t > 1e-6 else 1e3
    c_m = prm[C_M1] * (omega_t - prm[C_M2]) ** prm[C_M3] if omega_t > prm[W_TLIN] else prm[C_MLIN]
    eta_tm = turbine_efficiency(bsr, c_m, prm[ETA_TMMAX], prm[BSR_OPT])
    p_t = eta_tm * w_t * dh_t
    # --- compressor
    pi_c = p_im / prm[P_AMB]
    head = pi_c ** (1.0 - 1.0 / ga) - 1.0
    rcw = prm[R_C] * omega_t
    psi_c = max(2.0 * prm[C_PA] * t_amb * head / (rcw * rcw), prm[C_PSI2])
    c_psi1 = (prm[C_WPSI1] * omega_t + prm[C_WPSI2]) * omega_t + prm[C_WPSI3]
    c_phi1 = (prm[C_WPHI1] * omega_t + prm[C_WPHI2]) * omega_t + prm[C_WPHI3]
    dpsi = psi_c - prm[C_PSI2]
    phi_c = math.sqrt(max(0.0, (1.0 - c_psi1 * dpsi * dpsi) / c_phi1)) + prm[C_PHI2]
    w_c = prm[P_AMB] * math.pi * prm[R_C] ** 3 * omega_t * phi_c / (prm[R_A] * t_amb)
    dp = prm[P_AMB] - p_im
    if dp > 0.0:  # below ambient: the inlet/compressor passes flow as a restriction
        dl = prm[DP_LIN]
        f_dp = math.sqrt(dp) if dp >= dl else dp * (3.0 * dl - dp) / (2.0 * dl * math.sqrt(dl))
        w_c += prm[A_CR] * math.sqrt(2.0 * prm[P_AMB] / (prm[R_A] * t_amb)) * f_dp
        phi_c = w_c * prm[R_A] * t_amb / (prm[P_AMB] * math.pi * prm[R_C] ** 3 * omega_t)
    chi1 = w_c - prm[W_COPT]  # Q_c11, Q_c12 carry the flow scaling (AirpathScaling)
    chi2 = max(pi_c - 1.0, 0.0) ** prm[C_PI] - prm[PI_COPT]
    eta_c = prm[ETA_CMAX] - (
        prm[Q_C11] * chi1 * chi1 + 2.0 * prm[Q_C12] * chi1 * chi2 + prm[Q_C22] * chi2 * chi2
    )
    eta_c = min(max(eta_c, prm[ETA_MIN]), prm[ETA_CMAX])
    p_c = w_c * prm[C_PA] * t_amb * max(head, 0.0) / eta_c
    # --- oxygen/fuel ratio λ_O = W_ei X_Oim / (W_f (O/F)_s) is filled by the caller
    alg[A_W_C] = w_c
    alg[A_W_EGR] = w_egr
    alg[A_W_EI] = w_ei
    alg[A_W_F] = w_f
    alg[A_W_T] = w_t
    alg[A_T_EM] = t_em
    alg[A_T_E] = t_e
    alg[A_P_C] = p_c
    alg[A_P_T] = p_t
    alg[A_ETA_C] = eta_c
    alg[A_ETA_TM] = eta_tm
    alg[A_ETA_VOL] = eta_vol
    alg[A_PHI_C] = phi_c
    alg[A_PSI_EGR] = psi_egr
    alg[A_F_EGR] = fe
    alg[A_F_PIT] = f_pit
    alg[A_F_VGT] = fv
    alg[A_T1_NEW] = t1_new
    alg[A_XR_NEW] = xr_new
    alg[A_LAMBDA] = 0.0
    alg[A_BSR] = bsr


@nb.njit(cache=True)
def airpath_rhs(
    x: np.ndarray,
    mem: np.ndarray,
    fuel: float,
    speed: float,
    prm: np.ndarray,
    alg: np.ndarray,
    dx: np.ndarray,
) -> None:
    """Derivatives of the five gas/turbo states (LPV (1); W&E manifold and O₂ models).

    ``ṗ_im = R_a T_im/V_im (W_c + W_egr − W_ei)``,
    ``ṗ_em = R_e T_em/V_em (W_ei + W_f − W_t − W_egr)``,
    ``ω̇_t = (P_t η_m − P_c) / (J_t ω_t)``,
    ``Ẋ_Oim = R_a T_im/(p_im V_im) ((X_Oem − X_Oim) W_egr + (X_Oc − X_Oim) W_c)``,
    ``Ẋ_Oem = R_e T_em/(p_em V_em) (X_Oe − X_Oem) W_eo``,
    ``X_Oe = (W_ei X_Oim − W_f (O/F)_s) / W_eo`` with ``(O/F)_s = AFs · X_Oc``.
    ``dx[5:]`` (actuators) are integrated exactly elsewhere and set to 0 here.
    """
    p_im = x[0]
    p_em = x[1]
    w_t = x[2]
    u_egr = prm[K_EGR] * x[5] - (prm[K_EGR] - 1.0) * x[6]
    airpath_algebra(p_im, p_em, w_t, u_egr, x[7], fuel, speed, mem[0], mem[1], prm, alg)
    w_c = alg[A_W_C]
    w_egr = alg[A_W_EGR]
    w_ei = alg[A_W_EI]
    w_f = alg[A_W_F]
    w_eo = w_ei + w_f
    t_em = alg[A_T_EM]
    a1 = prm[R_A] * prm[T_IM] / prm[V_IM]
    a2 = prm[R_E] * t_em / prm[V_EM]
    dx[0] = a1 * (w_c + w_egr - w_ei)
    dx[1] = a2 * (w_eo - alg[A_W_T] - w_egr)
    dx[2] = (alg[A_P_T] - alg[A_P_C]) / (prm[J_T] * w_t)
    of_s = prm[AFS] * prm[X_OC]
    dx[3] = a1 / p_im * ((x[4] - x[3]) * w_egr + (prm[X_OC] - x[3]) * w_c)
    x_oe = max((w_ei * x[3] - w_f * of_s) / w_eo, 0.0) if w_eo > 1e-9 else x[4]
    dx[4] = a2 / p_em * (x_oe - x[4]) * w_eo
    dx[5] = 0.0
    dx[6] = 0.0
    dx[7] = 0.0
    alg[A_LAMBDA] = w_ei * x[3] / (w_f * of_s) if w_f > 1e-12 else 1e3


@nb.njit(cache=True)
def rho_from_algebra(
    p_im: float, p_em: float, omega_t: float, prm: np.ndarray, alg: np.ndarray, rho: np.ndarray
) -> None:
    """Scheduling vector of LPV (3) from the sub-model values.

    ``ρ1 = p_amb π R_c³ Φ_c / (R_a T_amb)`` (= W_c/ω_t), ``ρ2 = A_egr Ψ_egr / √(T_em R_e)``
    (= W_egr/p_em), ``ρ3 = η_vol n_e V_d / (120 R_a T_im)`` (= W_ei/p_im),
    ``ρ4 = A_vgtmax f_Πt f_vgt / √(T_em R_e)`` (= W_t/p_em),
    ``ρ5 = c_pa p_amb π R_c³ Φ_c (Π_c^(1−1/γa) − 1) / (J_t ω_t R_a η_c)`` (= P_c/(J_t ω_t²)).
    """
    sq_te = math.sqrt(alg[A_T_EM] * prm[R_E])
    rho[0] = prm[P_AMB] * math.pi * prm[R_C] ** 3 * alg[A_PHI_C] / (prm[R_A] * prm[T_AMB])
    rho[1] = prm[A_EGRMAX] * alg[A_F_EGR] * alg[A_PSI_EGR] / sq_te
    rho[2] = alg[A_W_EI] / p_im
    rho[3] = prm[A_VGTMAX] * alg[A_F_PIT] * alg[A_F_VGT] / sq_te
    head = max((p_im / prm[P_AMB]) ** (1.0 - 1.0 / prm[GAMMA_A]) - 1.0, 0.0)
    rho[4] = (
        prm[C_PA]
        * prm[P_AMB]
        * math.pi
        * prm[R_C] ** 3
        * alg[A_PHI_C]
        * head
        / (prm[J_T] * omega_t * prm[R_A] * alg[A_ETA_C])
    )


@nb.njit(cache=True)
def schedule_ff(fuel: float, speed: float, ctl: np.ndarray, out2: np.ndarray) -> None:
    """Feed-forward actuator maps and boost target (see ``ActuatorSchedule`` for the math).

    ``out2[0] = u_egr,ff`` (%), ``out2[1] = u_vgt,ff`` (%), ``out2[2] = Δp_ref`` (Pa above
    ambient).
    """
    load = min(max(fuel / ctl[FUEL_FULL], 0.0), 1.0)
    egr_load = min(max(1.0 - fuel / ctl[EGR_FUEL_OFF], 0.0), 1.0)
    egr_speed = min(max((ctl[EGR_SPEED_OFF] - speed) / ctl[EGR_SPEED_BAND], 0.0), 1.0)
    out2[0] = ctl[EGR_MAX] * egr_load * egr_speed
    boost_speed = min(
        max((speed - ctl[BOOST_N_LO]) / (ctl[BOOST_N_HI] - ctl[BOOST_N_LO]), 0.0), 1.0
    )
    out2[1] = ctl[VGT_MAX] - (ctl[VGT_MAX] - ctl[VGT_FF_CLOSED]) * load * boost_speed
    out2[2] = ctl[BOOST_MAX] * load * boost_speed


@nb.njit(cache=True)
def _interp_inputs(t: float, time_in: np.ndarray, vals: np.ndarray, j: int, out: np.ndarray) -> int:
    """Linear interpolation of the input columns at ``t`` (held beyond the ends).

    ``j`` is a hint index (the search moves forward only); returns the updated hint.
    """
    n = time_in.shape[0]
    if t <= time_in[0]:
        for c in range(vals.shape[1]):
            out[c] = vals[0, c]
        return 0
    if t >= time_in[n - 1]:
        for c in range(vals.shape[1]):
            out[c] = vals[n - 1, c]
        return n - 1
    while j < n - 2 and time_in[j + 1] <= t:
        j += 1
    eta = (t - time_in[j]) / (time_in[j + 1] - time_in[j])
    for c in range(vals.shape[1]):
        out[c] = vals[j, c] + eta * (vals[j + 1, c] - vals[j, c])
    return j


@nb.njit(cache=True, nogil=True)
def airpath_simulate_kernel(
    x: np.ndarray,
    mem: np.ndarray,
    time_in: np.ndarray,
    inputs: np.ndarray,
    use_controller: bool,
    t_out: np.ndarray,
    n_sub: int,
    n_warmup: int,
    prm: np.ndarray,
    ctl: np.ndarray,
    out: np.ndarray,
    diag: np.ndarray,
    progress: np.ndarray,
) -> None:
    """Integrate the plant over the whole horizon and record ``out[k, :]`` at ``t_out[k]``.

    ``inputs[m, 4]`` = (u_δ mg/cycle, n_e rpm, u_egr %, u_vgt %) at ``time_in[m]``, linearly
    interpolated; with ``use_controller`` the last two columns are ignored and the
    commands come from the feed-forward maps plus the boost PI (``ActuatorSchedule``), and
    the smoke limiter caps the injected fuel at ``λ_O ≥ λ_min`` (``out[:, O_FUEL]`` is the
    injected fuel, ``out[:, O_FUEL_DEMAND]`` the demand).
    Internal step ``h = (t_out[1] − t_out[0]) / n_sub``; ``n_warmup`` steps are run first
    with the inputs held at ``time_in[0]`` (settles the initial state).

    Scheme: Heun (explicit trapezoidal, 2nd order) for the five gas/turbo states with the
    actuator positions frozen over the step; the first-order actuators
    ``τ dũ/dt = u(t − τ_d) − ũ`` (W&E actuator models: VGT one lag, EGR two lags combined as
    ``ũ_egr = K_egr ũ_egr1 − (K_egr − 1) ũ_egr2``) are advanced exactly for the held
    (zero-order-hold) delayed command ``ũ ← u + (ũ − u) e^(−h/τ)``; the delays are ring
    buffers of whole steps. ``(T_1, x_r)`` take one fixed-point iteration per step. States
    leaving their physical box are clamped and counted in ``diag[D_CLAMPS]``.

    ``progress`` (int64, 2): ``[steps done, steps in all]``, written as it goes; the kernel
    releases the GIL, so another thread reads it live (:mod:`estimation.progress`).
    """
    n_out = t_out.shape[0]
    h = (t_out[1] - t_out[0]) / n_sub if n_out > 1 else 1e-3
    nx = x.shape[0]
    x1 = np.empty(nx)
    k1 = np.empty(nx)
    k2 = np.empty(nx)
    alg = np.empty(N_ALG)
    rho = np.empty(5)
    u_now = np.empty(4)
    ff = np.empty(3)
    n_d_egr = max(round(prm[TAU_DEGR] / h), 0)
    n_d_vgt = max(round(prm[TAU_DVGT] / h), 0)
    buf_egr = np.empty(n_d_egr + 1)
    buf_vgt = np.empty(n_d_vgt + 1)
    e_egr1 = math.exp(-h / prm[TAU_EGR1])
    e_egr2 = math.exp(-h / prm[TAU_EGR2])
    e_vgt = math.exp(-h / prm[TAU_VGT])
    p_amb = prm[P_AMB]
    integ = 0.0  # boost PI integral state (% of VGT position)
    j_hint = 0
    # initial command
    _interp_inputs(t_out[0], time_in, inputs, 0, u_now)
    schedule_ff(u_now[0], u_now[1], ctl, ff)
    if use_controller:
        cmd_egr0 = ff[0]
        cmd_vgt0 = ff[1]
    else:
        cmd_egr0 = u_now[2]
        cmd_vgt0 = u_now[3]
    for i in range(n_d_egr + 1):
        buf_egr[i] = cmd_egr0
    for i in range(n_d_vgt + 1):
        buf_vgt[i] = cmd_vgt0
    i_egr = 0
    i_vgt = 0
    cmd_egr = cmd_egr0
    cmd_vgt = cmd_vgt0
    p_ref = p_amb + ff[2]
    total = n_warmup + (n_out - 1) * n_sub + 1
    progress[0] = 0
    progress[1] = total
    k_out = 0
    for step in range(total):
        progress[0] = step
        t = t_out[0] + (step - n_warmup) * h if step >= n_warmup else t_out[0]
        j_hint = _interp_inputs(t, time_in, inputs, j_hint, u_now)
        fuel_demand = u_now[0]
        speed = u_now[1]
        fuel = fuel_demand
        if use_controller and ctl[LAMBDA_MIN] > 0.0:
            # smoke limiter: u_δ ≤ W_ei X_Oim / (λ_min (O/F)_s) · 120·10⁶ / (n_cyl n_e)
            eta_v = prm[C_VOL1] * math.sqrt(x[0]) + prm[C_VOL2] * math.sqrt(speed) + prm[C_VOL3]
            w_ei0 = eta_v * x[0] * speed * prm[V_D] / (120.0 * prm[R_A] * prm[T_IM])
            of_s = prm[AFS] * prm[X_OC]
            fuel_max = w_ei0 * x[3] / (ctl[LAMBDA_MIN] * of_s) * 120e6 / (prm[N_CYL] * speed)
            fuel = min(fuel, max(fuel_max, 0.0))
        # --- commands (controller at the internal rate)
        if use_controller:
            schedule_ff(fuel, speed, ctl, ff)
            p_ref = p_amb + ff[2]
            e = p_ref - x[0]
            guard = ctl[K_OMEGA] * max(x[2] - ctl[OMEGA_GUARD], 0.0) / ctl[OMEGA_GUARD]
            guard += ctl[K_PEM] * max(x[1] - ctl[P_EM_MAX], 0.0) / ctl[P_EM_MAX]
            raw = ff[1] - ctl[KP] * e - integ + guard
            lo = ctl[VGT_MIN]
            hi = ctl[VGT_MAX]
            cmd_vgt = min(max(raw, lo), hi)
            # conditional integration (anti-windup): integrate unless pushing into a limit
            d_int = ctl[KI] * e * h
            if not ((raw <= lo and d_int > 0.0) or (raw >= hi and d_int < 0.0)):
                integ += d_int
            integ = min(max(integ, -100.0), 100.0)
            cmd_egr = ff[0]
        else:
            cmd_egr = u_now[2]
            cmd_vgt = u_now[3]
        # --- record the state at the output instant
        if step >= n_warmup and (step - n_warmup) % n_sub == 0:
            airpath_rhs(x, mem, fuel, speed, prm, alg, k1)
            rho_from_algebra(x[0], x[1], x[2], prm, alg, rho)
            o = out[k_out]
            o[O_P_IM] = x[0]
            o[O_P_EM] = x[1]
            o[O_OMEGA_T] = x[2]
            o[O_XO_IM] = x[3]
            o[O_XO_EM] = x[4]
            o[O_U_EGR] = prm[K_EGR] * x[5] - (prm[K_EGR] - 1.0) * x[6]
            o[O_U_VGT] = x[7]
            o[O_U_EGR_CMD] = cmd_egr
            o[O_U_VGT_CMD] = cmd_vgt
            o[O_W_C] = alg[A_W_C]
            o[O_W_EGR] = alg[A_W_EGR]
            o[O_W_EI] = alg[A_W_EI]
            o[O_W_F] = alg[A_W_F]
            o[O_W_T] = alg[A_W_T]
            o[O_T_EM] = alg[A_T_EM]
            o[O_T_E] = alg[A_T_E]
            o[O_P_C] = alg[A_P_C]
            o[O_P_T] = alg[A_P_T]
            o[O_ETA_C] = alg[A_ETA_C]
            o[O_ETA_TM] = alg[A_ETA_TM]
            o[O_ETA_VOL] = alg[A_ETA_VOL]
            o[O_FUEL] = fuel
            o[O_SPEED] = speed
            o[O_DP_IM] = k1[0]
            o[O_DP_EM] = k1[1]
            o[O_DOMEGA_T] = k1[2]
            for r in range(5):
                o[O_RHO1 + r] = rho[r]
            o[O_P_IM_REF] = p_ref
            o[O_LAMBDA] = alg[A_LAMBDA]
            we = alg[A_W_EGR]
            o[O_EGR_FRAC] = we / (we + alg[A_W_C]) if we + alg[A_W_C] > 0.0 else 0.0
            o[O_BSR] = alg[A_BSR]
            o[O_FUEL_DEMAND] = fuel_demand
            k_out += 1
            if k_out == n_out:
                break
        # --- Heun step of the gas/turbo states
        airpath_rhs(x, mem, fuel, speed, prm, alg, k1)
        t1_new = alg[A_T1_NEW]
        xr_new = alg[A_XR_NEW]
        for i in range(nx):
            x1[i] = x[i] + h * k1[i]
        airpath_rhs(x1, mem, fuel, speed, prm, alg, k2)
        for i in range(5):
            x[i] += 0.5 * h * (k1[i] + k2[i])
        mem[0] = t1_new
        mem[1] = xr_new
        # --- actuators: delayed command, exact first-order update
        buf_egr[i_egr] = cmd_egr
        i_egr = (i_egr + 1) % (n_d_egr + 1)
        u_egr_d = buf_egr[i_egr]  # the oldest entry = command n_d steps ago
        buf_vgt[i_vgt] = cmd_vgt
        i_vgt = (i_vgt + 1) % (n_d_vgt + 1)
        u_vgt_d = buf_vgt[i_vgt]
        x[5] = u_egr_d + (x[5] - u_egr_d) * e_egr1
        x[6] = u_egr_d + (x[6] - u_egr_d) * e_egr2
        x[7] = u_vgt_d + (x[7] - u_vgt_d) * e_vgt
        # --- safety box (counted; a healthy run has zero clamps)
        clamped = False
        if x[0] < 0.3 * p_amb:
            x[0] = 0.3 * p_amb
            clamped = True
        if x[1] < 0.5 * p_amb:
            x[1] = 0.5 * p_amb
            clamped = True
        if x[2] < prm[OMEGA_T_MIN]:
            x[2] = prm[OMEGA_T_MIN]
            clamped = True
        if x[2] > prm[OMEGA_T_MAX]:
            x[2] = prm[OMEGA_T_MAX]
            clamped = True
        for i in (3, 4):
            if x[i] < 0.0:
                x[i] = 0.0
                clamped = True
            elif x[i] > prm[X_OC]:
                x[i] = prm[X_OC]
                clamped = True
        if clamped:
            diag[D_CLAMPS] += 1


@nb.njit(cache=True)
def airpath_rho_kernel(
    p_im: np.ndarray,
    p_em: np.ndarray,
    omega_t: np.ndarray,
    u_egr_pos: np.ndarray,
    u_vgt_pos: np.ndarray,
    fuel: np.ndarray,
    speed: np.ndarray,
    n_iter: int,
    prm: np.ndarray,
    rho_out: np.ndarray,
    t_em_out: np.ndarray,
    w_egr_out: np.ndarray,
) -> None:
    """ρ (LPV (3)), ``T_em`` and ``W_egr`` from (measured) signals, sample by sample.

    The Seiliger fixed point ``(T_1, x_r)`` is iterated ``n_iter`` times per sample starting
    from ``(T_im, 0)`` (it contracts by about ``x_r`` ≈ 0.05 per iteration); the iterations
    before the last run :func:`exhaust_iterate` alone, the last the whole algebra, which
    gives the bits of running the whole algebra every time.
    """
    alg = np.empty(N_ALG)
    rho = np.empty(5)
    for k in range(p_im.shape[0]):
        t1 = prm[T_IM]
        xr = 0.0
        for _ in range(n_iter - 1):
            iterate = exhaust_iterate(p_im[k], p_em[k], fuel[k], speed[k], t1, xr, prm)
            t1, xr = iterate[5], iterate[6]
        airpath_algebra(
            p_im[k], p_em[k], omega_t[k], u_egr_pos[k], u_vgt_pos[k], fuel[k], speed[k],
            t1, xr, prm, alg,
        )  # fmt: skip
        rho_from_algebra(p_im[k], p_em[k], omega_t[k], prm, alg, rho)
        for r in range(5):
            rho_out[k, r] = rho[r]
        t_em_out[k] = alg[A_T_EM]
        w_egr_out[k] = alg[A_W_EGR]
