"""Parameters of the diesel air-path plant: the Scania reference set and its scaling to ~2 L.

The reference values are the published parameter set of Wahlström & Eriksson (2011) for a
12.7 L six-cylinder Scania engine (``/work/shared/models/wahlstrom-eriksson-scania-
parameters.txt``). :class:`AirpathScaling` states how they are carried over to a ~2.0 L
four-cylinder common-rail diesel (the LPV paper's engine is a 1.9 L four-cylinder);
:class:`AirpathParams` holds the resulting values under their W&E symbols, and
:class:`ActuatorSchedule` the feed-forward maps and boost controller that turn a cycle of
``(u_δ, n_e)`` into ``(u_egr, u_vgt)``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from estimation.errors import ConfigError
from estimation.kernels.airpath_plant import CTRL_NAMES, PARAM_NAMES

# W&E (2011) Scania parameter set, SI units, copied from the parameter file (only the
# values the model uses; the file's *_Init entries are initial conditions).
SCANIA_REFERENCE: dict[str, float] = {
    "c_pa": 1011.0,  # J/(kg K)
    "c_pe": 1332.0,  # J/(kg K)
    "R_a": 287.0,  # J/(kg K)
    "R_e": 286.0,  # J/(kg K)
    "c_va": 724.0,  # J/(kg K)
    "gamma_a": 1.3964088398,
    "gamma_e": 1.2734225621,
    "T_amb": 298.4636219512,  # K
    "p_amb": 101111.3414634146,  # Pa
    "V_im": 0.022,  # m³
    "T_im": 300.6185731707,  # K
    "V_em": 0.02,  # m³
    "r_c": 17.0,
    "V_d": 0.01274,  # m³ (total displacement)
    "q_HV": 42.9e6,  # J/kg
    "AFs": 14.57,
    "n_cyl": 6.0,
    "h_tot": 96.2754598402,  # W/(m² K)
    "d_pipe": 0.1,  # m
    "l_pipe": 1.0,  # m
    "n_pipe": 2.0,
    "R_c": 0.04,  # m
    "c_psi2": 0.0,
    "c_phi2": 0.0,
    "c_wpsi1": 1.0882051053e-08,  # (s/rad)²
    "c_wpsi2": -1.7319760360e-04,  # s/rad
    "c_wpsi3": 1.0286164756e00,
    "c_wphi1": -1.4297782685e-08,  # (s/rad)²
    "c_wphi2": -1.5498814146e-03,  # s/rad
    "c_wphi3": 2.9646172151e01,
    "Q_c11": 3.0918977685,
    "Q_c12": -2.4823201383,
    "Q_c22": 2.147855962,
    "eta_cmax": 0.736360788,
    "W_copt": 0.2753375746,  # kg/s
    "pi_copt": 1.0455177468,
    "c_pi": 0.2707594739,
    "c_vol1": -2.0816619843e-04,  # Pa^-1/2
    "c_vol2": -3.4465158053e-03,  # rpm^-1/2
    "c_vol3": 1.1497021021e00,
    "eta_sc": 1.1015294625,
    "x_cv": 2.3370584442e-14,
    "A_egrmax": 0.0004,  # m²
    "tau_degr": 0.065,  # s
    "PI_egropt": 0.6500040483,
    "A_vgtmax": 0.0008455767,  # m²
    "R_t": 0.04,  # m
    "BSR_opt": 0.9755203162,
    "c_m1": 1.3563440681e00,
    "c_m2": 2.7692092016e03,  # rad/s
    "c_m3": 1.0000098745e-02,
    "w_tlin": 2796.9012935925,  # rad/s
    "c_mlin": 1.4021470818,
    "tau_vgt": 0.025,  # s
    "K_t": 2.8901926611,
    "c_f1": 1.9479627004,
    "c_f2": -0.7763118933,
    "c_vgt1": 126.8719357229,  # %
    "c_vgt2": 117.1447468823,  # %
    "J_t": 0.0002,  # kg m²
    "c_egr1": -0.0001110424,  # %^-2
    "c_egr2": 0.0177806123,  # %^-1
    "c_egr3": 0.0,
    "eta_tmmax": 0.8180027269,
    "tau_egr1": 0.05,  # s
    "tau_egr2": 0.13,  # s
    "K_egr": 1.8,
    "tau_dvgt": 0.04,  # s
    "X_Oc": 0.2314,
}


@dataclass(frozen=True, slots=True)
class AirpathScaling:
    """How the Scania set becomes a ~2 L four-cylinder engine (every rule, with units).

    Let ``k_V = displacement_m3 / 0.01274`` (engine displacement ratio), ``λ =
    ((displacement_m3/n_cyl) / (0.01274/6))^(1/3)`` (cylinder length ratio: stroke, bore) and
    ``s = turbo_scale`` (turbocharger length ratio: wheel radii).

    - ``V_d ← displacement_m3``, ``n_cyl ← n_cyl``; ``V_im, V_em ← k_V ·`` Scania (manifold
      volumes proportional to displacement).
    - Volumetric efficiency ``η_vol(p_im, n_e)`` is evaluated at the Scania mean piston
      speed: ``n_e,ref = λ n_e`` ⇒ ``c_vol2 ← c_vol2 √λ``.
    - Turbocharger: geometric similarity at equal tip speed. ``R_c, R_t ← s ·``;
      turbo speed ``ω_t = ω_t,ref / s`` ⇒ the ω-polynomials ``c_Ψ1(ω), c_Φ1(ω)`` get
      ``c_w·1 ← c_w·1 s²``, ``c_w·2 ← c_w·2 s``; ``c_m1 ← c_m1 s^c_m3``, ``c_m2, ω_tlin ← /s``.
      Flows at equal pressure ratio scale with ``R_c³ ω_t ∝ s²``: ``W_copt, A_vgtmax,
      A_egrmax ← s² ·``; the efficiency map is read at the Scania flow ``W_c / s²``
      ⇒ ``Q_c11 ← Q_c11 / s⁴``, ``Q_c12 ← Q_c12 / s²``.
    - Turbine matching: ``A_vgtmax ← turbine_area_factor · s² · A_vgtmax`` with factor 1.3;
      with 1.0 the VGT saturates fully open at full load above ~3000 rpm and the boost and
      turbo speed can no longer be held (2.8 bar, 19 900 rad/s at 3500 rpm).
    - Turbo inertia ``J_t = J_t_kg_m2 = 2.5·10⁻⁵ kg m²`` (order of passenger-car VGT
      rotors); the similar-rotor rule ``s⁵ J_t,ref = 1.0·10⁻⁵`` (``J_t_kg_m2=None``) gives
      ρ5 up to ≈ 9 1/s, three times LPV Table 1's maximum 3.15.
    - Below ambient, an inlet restriction of ``inlet_restriction_area_m2`` passes flow in
      parallel to the compressor map (ours; see the kernel).
    - Exhaust-pipe heat-loss area ``π d_pipe l_pipe n_pipe ← s² ·`` (same temperature drop
      at corresponding flows).
    - Dimensionless maps (Φ_c(Ψ_c), η_c, f_vgt, f_egr, Ψ_egr, η_tm(BSR), Seiliger cycle),
      gas properties, ambient, actuator time constants and delays: unchanged.
    - Fuel range: the Scania's 1–250 mg/cycle/cyl × (cylinder volume ratio λ³ ≈ 0.24)
      ≈ 0–59 mg/cycle; the LPV grid's 56 mg/cycle is full load (``ActuatorSchedule``).

    Defaults: 2.0 L, 4 cylinders, ``s = 0.55`` (compressor wheel radius 22 mm; peak
    compressor flow ≈ 0.18 kg/s, enough for 2 L at 4000 rpm and 2.3 bar).
    """

    displacement_m3: float = 0.0020
    n_cyl: int = 4
    turbo_scale: float = 0.55
    omega_t_min_rad_s: float = 200.0  # safety box (counted clamp), not a physical limit
    omega_t_max_rad_s: float = 30000.0  # safety box; the controller guards 19 000 rad/s
    eta_min: float = 0.2  # floor of the compressor efficiency fit (ours)
    z_lin: float = 0.01  # turbine f_Πt regularisation below 1 − Π_t^K_t = z_lin (ours)
    turbine_area_factor: float = 1.3  # extra factor on A_vgtmax beyond s² (turbine matching)
    inlet_restriction_area_m2: float = 1.0e-3  # A_cr: flow below ambient (ours; ~36 mm dia)
    dp_lin_pa: float = 500.0  # regularisation of the restriction flow near Δp = 0
    J_t_kg_m2: float | None = 2.5e-5  # turbo inertia; None: similar-rotor rule s⁵ J_t,ref

    def __post_init__(self) -> None:
        if not 1e-4 <= self.displacement_m3 <= 0.05:
            raise ConfigError(
                f"displacement_m3 must be in [1e-4, 0.05] m³, got {self.displacement_m3}"
            )
        if self.n_cyl not in (2, 3, 4, 5, 6, 8):
            raise ConfigError(f"n_cyl must be one of 2, 3, 4, 5, 6, 8, got {self.n_cyl}")
        if not 0.2 <= self.turbo_scale <= 2.0:
            raise ConfigError(f"turbo_scale must be in [0.2, 2], got {self.turbo_scale}")
        if not 0.0 < self.omega_t_min_rad_s < self.omega_t_max_rad_s:
            raise ConfigError(
                f"need 0 < omega_t_min_rad_s < omega_t_max_rad_s, got "
                f"{self.omega_t_min_rad_s}, {self.omega_t_max_rad_s}"
            )
        if not 0.0 < self.eta_min < 0.7:
            raise ConfigError(f"eta_min must be in (0, 0.7), got {self.eta_min}")
        if not 0.0 < self.z_lin < 0.2:
            raise ConfigError(f"z_lin must be in (0, 0.2), got {self.z_lin}")
        if not 0.2 <= self.turbine_area_factor <= 5.0:
            raise ConfigError(
                f"turbine_area_factor must be in [0.2, 5], got {self.turbine_area_factor}"
            )
        if not 0.0 <= self.inlet_restriction_area_m2 <= 0.05:
            raise ConfigError(
                f"inlet_restriction_area_m2 must be in [0, 0.05] m², got "
                f"{self.inlet_restriction_area_m2}"
            )
        if self.J_t_kg_m2 is not None and not 1e-7 <= self.J_t_kg_m2 <= 1e-2:
            raise ConfigError(f"J_t_kg_m2 must be in [1e-7, 1e-2] kg m², got {self.J_t_kg_m2}")
        if not self.dp_lin_pa > 0.0:
            raise ConfigError(f"dp_lin_pa must be > 0 Pa, got {self.dp_lin_pa}")

    @property
    def displacement_ratio(self) -> float:
        """``k_V`` = displacement / Scania displacement."""
        return self.displacement_m3 / SCANIA_REFERENCE["V_d"]

    @property
    def cylinder_length_ratio(self) -> float:
        """``λ`` = (cylinder volume / Scania cylinder volume)^(1/3)."""
        ref = SCANIA_REFERENCE["V_d"] / SCANIA_REFERENCE["n_cyl"]
        return (self.displacement_m3 / self.n_cyl / ref) ** (1.0 / 3.0)


@dataclass(frozen=True, slots=True)
class AirpathParams:
    """Model parameters under their W&E symbols (SI; see ``SCANIA_REFERENCE`` for units).

    Extra symbols: ``hA_pipe = h_tot π d_pipe l_pipe n_pipe`` [W/K]; ``eta_min`` (floor of
    ``η_c``), ``z_lin`` (turbine regularisation), ``omega_t_min/max`` [rad/s] (safety box).
    Build with :meth:`scaled` (default ~2 L engine) or :meth:`scania`.
    """

    R_a: float
    R_e: float
    c_pa: float
    c_pe: float
    c_va: float
    gamma_a: float
    gamma_e: float
    T_amb: float
    p_amb: float
    T_im: float
    V_im: float
    V_em: float
    r_c: float
    V_d: float
    n_cyl: float
    q_HV: float
    AFs: float
    X_Oc: float
    hA_pipe: float
    c_vol1: float
    c_vol2: float
    c_vol3: float
    eta_sc: float
    x_cv: float
    R_c: float
    c_wpsi1: float
    c_wpsi2: float
    c_wpsi3: float
    c_wphi1: float
    c_wphi2: float
    c_wphi3: float
    c_psi2: float
    c_phi2: float
    Q_c11: float
    Q_c12: float
    Q_c22: float
    eta_cmax: float
    W_copt: float
    pi_copt: float
    c_pi: float
    A_egrmax: float
    PI_egropt: float
    c_egr1: float
    c_egr2: float
    c_egr3: float
    tau_egr1: float
    tau_egr2: float
    K_egr: float
    tau_degr: float
    A_vgtmax: float
    R_t: float
    BSR_opt: float
    c_m1: float
    c_m2: float
    c_m3: float
    w_tlin: float
    c_mlin: float
    K_t: float
    c_f1: float
    c_f2: float
    c_vgt1: float
    c_vgt2: float
    eta_tmmax: float
    tau_vgt: float
    tau_dvgt: float
    J_t: float
    eta_min: float
    z_lin: float
    omega_t_min: float
    omega_t_max: float
    A_cr: float
    dp_lin: float

    @classmethod
    def scania(cls, *, scaling: AirpathScaling | None = None) -> AirpathParams:
        """The unscaled 12.7 L Scania set (only the numerical safeguards of ``scaling``)."""
        sc = scaling or AirpathScaling()
        ref = SCANIA_REFERENCE
        values = {f.name: ref[f.name] for f in fields(cls) if f.name in ref}
        values["hA_pipe"] = ref["h_tot"] * math.pi * ref["d_pipe"] * ref["l_pipe"] * ref["n_pipe"]
        values["eta_min"] = sc.eta_min
        values["z_lin"] = sc.z_lin
        values["omega_t_min"] = sc.omega_t_min_rad_s * sc.turbo_scale
        values["omega_t_max"] = sc.omega_t_max_rad_s * sc.turbo_scale
        values["A_cr"] = sc.inlet_restriction_area_m2 / sc.turbo_scale**2
        values["dp_lin"] = sc.dp_lin_pa
        return cls(**values)

    @classmethod
    def scaled(cls, scaling: AirpathScaling | None = None) -> AirpathParams:
        """Apply every rule of :class:`AirpathScaling` to the Scania set."""
        sc = scaling or AirpathScaling()
        base = cls.scania(scaling=sc)
        k_v = sc.displacement_ratio
        lam = sc.cylinder_length_ratio
        s = sc.turbo_scale
        s2 = s * s
        return replace(
            base,
            V_d=sc.displacement_m3,
            n_cyl=float(sc.n_cyl),
            V_im=base.V_im * k_v,
            V_em=base.V_em * k_v,
            c_vol2=base.c_vol2 * math.sqrt(lam),
            R_c=base.R_c * s,
            R_t=base.R_t * s,
            c_wpsi1=base.c_wpsi1 * s2,
            c_wpsi2=base.c_wpsi2 * s,
            c_wphi1=base.c_wphi1 * s2,
            c_wphi2=base.c_wphi2 * s,
            c_m1=base.c_m1 * s**base.c_m3,
            c_m2=base.c_m2 / s,
            w_tlin=base.w_tlin / s,
            W_copt=base.W_copt * s2,
            Q_c11=base.Q_c11 / (s2 * s2),
            Q_c12=base.Q_c12 / s2,
            A_vgtmax=base.A_vgtmax * s2 * sc.turbine_area_factor,
            A_egrmax=base.A_egrmax * s2,
            hA_pipe=base.hA_pipe * s2,
            J_t=base.J_t * s**5 if sc.J_t_kg_m2 is None else sc.J_t_kg_m2,
            A_cr=sc.inlet_restriction_area_m2,
            omega_t_min=sc.omega_t_min_rad_s,
            omega_t_max=sc.omega_t_max_rad_s,
        )

    @property
    def a1(self) -> float:
        """LPV (5) ``a1 = R_a T_im / V_im`` [J/(kg m³)] — exact: W&E take T_im constant."""
        return self.R_a * self.T_im / self.V_im

    def a2(self, T_em: float) -> float:
        """LPV (5) ``a2 = R_e T_em / V_em`` at the exhaust temperature ``T_em`` [K]."""
        return self.R_e * T_em / self.V_em

    def to_vector(self) -> np.ndarray:
        """The kernel's parameter vector (order ``PARAM_NAMES``)."""
        return np.array([getattr(self, n) for n in PARAM_NAMES], dtype=np.float64)

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}


@dataclass(frozen=True, slots=True)
class ActuatorSchedule:
    """Feed-forward actuator maps and a boost PI that drive the plant from ``(u_δ, n_e)``.

    With ``L = clip(u_δ / fuel_full_mg, 0, 1)`` (load) and
    ``S = clip((n_e − boost_speed_lo_rpm)/(boost_speed_hi_rpm − boost_speed_lo_rpm), 0, 1)``:

    - EGR (feed-forward only): ``u_egr = egr_max_pct · clip(1 − u_δ/egr_fuel_off_mg, 0, 1)
      · clip((egr_speed_off_rpm − n_e)/egr_speed_band_rpm, 0, 1)`` — EGR at light and part
      load, closed at high load and high speed (usual passenger-car practice).
    - Boost target: ``p_im,ref = p_amb + boost_max_pa · L · S``.
    - VGT: ``u_vgt = clip(u_ff − K_p e − I + K_ω max(ω_t − ω_guard, 0)/ω_guard + …,
      vgt_min_pct, vgt_max_pct)``, ``u_ff = vgt_max − (vgt_max − vgt_ff_closed) L S``,
      ``e = p_im,ref − p_im``, ``İ = K_i e`` with conditional integration (anti-windup).
      Closing the VGT (lower %) raises boost, so the loop gain is negative in %/Pa.
      The ω-term opens the VGT when the turbo overspeeds; likewise
      ``+ K_pem max(p_em − p_em,max, 0)/p_em,max`` when the exhaust pressure exceeds its limit.
    - Smoke limiter (as in every diesel ECU): the injected fuel is
      ``min(u_δ,demand, W_ei X_Oim / (λ_min (O/F)_s) · 120·10⁶ / (n_cyl n_e))`` so the
      oxygen/fuel ratio stays ``λ_O ≥ lambda_min``; ``lambda_min = 0`` disables it.
    """

    fuel_full_mg: float = 56.0
    egr_max_pct: float = 60.0
    egr_fuel_off_mg: float = 32.0
    egr_speed_off_rpm: float = 3600.0
    egr_speed_band_rpm: float = 1000.0
    vgt_min_pct: float = 20.0
    vgt_max_pct: float = 100.0
    vgt_ff_closed_pct: float = 45.0
    boost_max_pa: float = 1.3e5
    boost_speed_lo_rpm: float = 900.0
    boost_speed_hi_rpm: float = 2000.0
    kp_pct_per_pa: float = 1.5e-4
    ki_pct_per_pa_s: float = 3.0e-4
    omega_guard_rad_s: float = 19000.0
    k_omega_pct: float = 300.0
    lambda_min: float = 1.2  # smoke limiter (0 disables): injected u_δ keeps λ_O ≥ lambda_min
    p_em_max_pa: float = 3.2e5
    k_pem_pct: float = 300.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not math.isfinite(v) or v < 0:
                raise ConfigError(f"ActuatorSchedule.{f.name} must be finite and ≥ 0, got {v}")
        if not 0.0 <= self.vgt_min_pct < self.vgt_max_pct <= 100.0:
            raise ConfigError(
                f"need 0 ≤ vgt_min_pct < vgt_max_pct ≤ 100, got {self.vgt_min_pct}, "
                f"{self.vgt_max_pct}"
            )
        if self.boost_speed_hi_rpm <= self.boost_speed_lo_rpm:
            raise ConfigError(
                f"boost_speed_hi_rpm ({self.boost_speed_hi_rpm}) must exceed "
                f"boost_speed_lo_rpm ({self.boost_speed_lo_rpm})"
            )
        for name in ("fuel_full_mg", "egr_fuel_off_mg", "egr_speed_band_rpm", "omega_guard_rad_s"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"ActuatorSchedule.{name} must be > 0, got {getattr(self, name)}")

    def to_vector(self) -> np.ndarray:
        """The kernel's controller vector (order ``CTRL_NAMES``)."""
        order = (
            self.fuel_full_mg,
            self.egr_max_pct,
            self.egr_fuel_off_mg,
            self.egr_speed_off_rpm,
            self.egr_speed_band_rpm,
            self.vgt_min_pct,
            self.vgt_max_pct,
            self.vgt_ff_closed_pct,
            self.boost_max_pa,
            self.boost_speed_lo_rpm,
            self.boost_speed_hi_rpm,
            self.kp_pct_per_pa,
            self.ki_pct_per_pa_s,
            self.omega_guard_rad_s,
            self.k_omega_pct,
            self.lambda_min,
            self.p_em_max_pa,
            self.k_pem_pct,
        )
        assert len(order) == len(CTRL_NAMES)
        return np.array(order, dtype=np.float64)

    def to_dict(self) -> dict[str, Any]:
        return {k: float(v) for k, v in asdict(self).items()}
