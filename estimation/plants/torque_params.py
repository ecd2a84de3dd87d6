"""Parameters of the torque plants: the SI engine of TQ §VI and the diesel rig of TQ §VII.

Each field says where its value comes from: "TQ" = an input the paper states (its §VI/§VII
set-up, never its result tables, Tables III–VII); otherwise a physical estimate or a typical
data-sheet value for such an engine, test bed or sensor, with the numbers it rests on. The
firing ripple as a test-bed shaft passes it is :func:`shaft_ripple_rel`, the dyno's encoder
speed noise :func:`encoder_speed_noise_std_rpm`, the load cell's noise
:func:`load_cell_noise_std_nm`. :func:`si_coefficients` and
:func:`rig_coefficients` pack a parameter set into the coefficient vector of
:mod:`estimation.kernels.torque_plant`; :func:`validate_params` checks what both share. The
simulators that use them are in :mod:`estimation.plants.torque`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from estimation.errors import ConfigError
from estimation.kernels import torque_plant as kp

__all__ = [
    "CRANK_RIPPLE_REL",
    "DYNO_INERTIA_SHARE",
    "SHAFT_MODE_HZ",
    "VARIANCE_20_STD",
    "DieselRigParams",
    "SiEngineParams",
    "encoder_speed_noise_std_rpm",
    "load_cell_noise_std_nm",
    "require_positive",
    "rig_coefficients",
    "shaft_ripple_rel",
    "si_coefficients",
    "validate_params",
]

VARIANCE_20_STD: float = math.sqrt(20.0)
"""σ of TQ §VI's ``N(0, 20)`` (a stated input) read as variance 20, the ``N(μ, σ²)``
convention (see :mod:`estimation.plants.torque`)."""

CRANK_RIPPLE_REL: tuple[float, float] = (1.0, 0.3)
"""Amplitudes of the firing-order and twice-firing-order harmonics of a four-cylinder's crank
torque, relative to the mean indicated torque, at part load (order of magnitude). At 2200 rpm
a 2 L four-cylinder's second-order (= firing-order) *inertia* torque is
``2·m·r²·ω² ≈ 2·0.5 kg·(0.043 m)²·(230 rad/s)² ≈ 98 N·m`` (reciprocating mass 0.5 kg per
cylinder, half-stroke 43 mm); the gas torque's firing-order harmonic at bmep ≈ 5 bar is of the
same order (the tangential-pressure harmonic coefficients of a four-stroke cylinder). Both are
of the order of the mean τ_i (≈ 110 N·m here), hence 1.0; the next firing harmonic is roughly
a third of the first."""

SHAFT_MODE_HZ: float = 15.0
"""First torsional mode of the engine–coupling–dynamometer shaft [Hz]. Test-bed shafts carry
a soft coupling that places it below the idle firing frequency (a four-cylinder at 800 rpm
fires at 27 Hz), typically 5–20 Hz; 15 Hz is mid-range."""

DYNO_INERTIA_SHARE: float = 0.5
"""``J_d/(J_e + J_d)``: the dynamometer rotor's share of the shaft-line inertia [-] (a
dynamometer rotor of the engine's own inertia, 0.1–0.3 kg·m²)."""


def shaft_ripple_rel(
    speed_rpm: float,
    *,
    n_cylinders: int = 4,
    crank_rel: tuple[float, float] = CRANK_RIPPLE_REL,
    mode_hz: float = SHAFT_MODE_HZ,
    dyno_share: float = DYNO_INERTIA_SHARE,
) -> tuple[float, float]:
    """Firing ripple of the torque a test-bed shaft transmits, relative to the mean τ_i.

    The crank-torque harmonic ``crank_rel[h]`` at ``f_h = (h + 1)·N·n_cyl/120`` Hz passes an
    undamped two-inertia shaft (engine, coupling stiffness, dynamometer) as
    ``|T_shaft/T| = dyno_share/((f_h/f_n)² − 1)`` above its mode ``f_n`` (the engine inertia
    takes the rest). Example, the SI defaults at 2200 rpm (73 Hz):

    >>> [round(r, 4) for r in shaft_ripple_rel(2200.0)]
    [0.0218, 0.0016]
    """
    out = []
    for h, rel in enumerate(crank_rel):
        ratio = (h + 1) * speed_rpm * n_cylinders / 120.0 / mode_hz
        if ratio <= 1.0:
            raise ConfigError(
                f"shaft_ripple_rel: harmonic {h + 1} at {speed_rpm:g} rpm is not above the "
                f"shaft mode {mode_hz:g} Hz"
            )
        out.append(rel * dyno_share / (ratio * ratio - 1.0))
    return out[0], out[1]


ENCODER_LINES: int = 1024
"""Lines of the dynamometer's speed encoder (a 1024-line incremental encoder, counted on both
edges of both tracks: 4096 counts per revolution)."""


def encoder_speed_noise_std_rpm(
    *, lines: int = ENCODER_LINES, sample_period_s: float = 1e-3
) -> float:
    """σ [rpm] of a speed counted from a quadrature encoder over each sample period: one count
    is ``q = 60/(4·lines·Ts)`` rpm, and a uniform quantisation error has ``σ = q/√12``.

    >>> round(encoder_speed_noise_std_rpm(), 2)
    4.23
    """
    return 60.0 / (4.0 * lines * sample_period_s) / math.sqrt(12.0)


LOAD_CELL_RANGE_NM: float = 500.0
"""Range of the rig's torque measurement [N·m]: a 500 N·m flange for a 320 N·m engine."""

LOAD_CELL_ACCURACY: float = 1.0e-3
"""Accuracy class of the torque measurement, 0.1 % of range (test-bed torque flanges and load
cells are specified at 0.05–0.1 %)."""


def load_cell_noise_std_nm(
    *, range_nm: float = LOAD_CELL_RANGE_NM, accuracy: float = LOAD_CELL_ACCURACY
) -> float:
    """σ [N·m] of the load-torque channel: the accuracy class taken as the 1σ noise of each
    1 kHz reading (pessimistic: the class bounds the whole error, drift included).

    >>> load_cell_noise_std_nm()
    0.5
    """
    return range_nm * accuracy


_SI_RIPPLE = shaft_ripple_rel(2200.0)  # TQ §VI's first set-point
_RIG_RIPPLE = shaft_ripple_rel(1750.0)  # middle of TQ §VII's 1000–2500 rpm sweep


class _EngineParams:
    """What both parameter sets derive from their fields (a slot-less mixin)."""

    __slots__ = ()
    inertia_kg_m2: float

    @property
    def J_nm_s_per_rpm(self) -> float:
        """Scaled inertia of TQ (8) with N in rpm: ``J = inertia·2π/60`` [N·m·s/rpm]."""
        return self.inertia_kg_m2 * kp.RPM_TO_RAD_S

    def to_dict(self) -> dict[str, Any]:
        """JSON-able parameters (tuples become lists) plus the derived scaled inertia."""
        d = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
        d["J_nm_s_per_rpm"] = self.J_nm_s_per_rpm
        return d


@dataclass(frozen=True, slots=True)
class SiEngineParams(_EngineParams):
    """SI engine, dyno and scenario of TQ §VI. Source per field: "TQ" = given in the paper,
    otherwise a plausible value for a ~2 L naturally aspirated port-injected SI engine (TQ
    §II models this engine; its §VI GT-Power model is a 2.0 L turbo DI SI whose data TQ does
    not give).
    """

    inertia_kg_m2: float = 0.15
    """Crank-train inertia [kg·m²]; not in TQ. A 2 L four-cylinder's crankshaft with damper
    and pulley (≈ 0.03–0.05), connecting-rod big ends and pistons' rotating share (≈ 0.01) and
    a single-mass flywheel (8–10 kg, ≈ 0.08–0.12) sum to 0.1–0.2 kg·m²; 0.15 is mid-range. The
    UIO passes the speed noise as ``J/k·(w1 − w1f)`` (TQ (30)), so with §VI's ``σ_N = √20``
    rpm its noise floor alone is ``≈ (J/k)·σ_N ≈ 7.0`` N·m SD (docs/fidelity.md#held-out)."""
    displacement_m3: float = 2.0e-3  # V_d [m³]; TQ §VI: 2.0 L
    manifold_volume_m3: float = 2.5e-3  # V_m [m³]; ≈ V_d, manifold time constant ≈ 50 ms
    gas_constant_j_kg_k: float = 287.0  # R of air [J/(kg·K)]
    kappa: float = 1.4  # TQ (1): κ = 1.4 for air
    ambient_temp_k: float = 298.0  # T_a [K]
    manifold_temp_k: float = 298.0
    """T_m [K]. Equal to T_a by default: with T_m ≠ T_a, TQ (1) forces ṁ_ai·T_a = ṁ_ao·T_m in
    steady state, i.e. the constant-temperature manifold of TQ (1) does not conserve mass."""
    ambient_pressure_pa: float = 101_325.0  # p_a [Pa]
    eta_vol_coef: tuple[float, float, float] = (0.70, 0.14, -0.022)
    """η_vol = c0 + c1·(N/1000) + c2·(N/1000)² [-]: 0.90 at 2200 rpm, 0.91 at 2500 rpm."""
    fuel_heating_value_j_kg: float = 43.0e6  # H_u [J/kg], gasoline LHV
    eta_i_max: float = 0.40  # η_i = η_max·(1 − c·exp(−N/N_c)) [-]
    eta_i_c: float = 0.35
    eta_i_speed_rpm: float = 1000.0  # N_c [rpm]
    lambda_ratio: float = 1.0  # λ (stoichiometric SI)
    stoich_afr: float = 14.7  # TQ (4): L_th = 14.7 for petrol
    friction_coef: tuple[float, float, float] = (8.0, 2.0e-3, 1.5e-6)
    """TQ (6) a0 [N·m], a1 [N·m/rpm], a2 [N·m/rpm²]: τ_f ≈ 20 N·m (FMEP ≈ 1.3 bar) at 2200."""
    n_cylinders: int = 4  # TQ §VI: four-cylinder
    ripple_rel: tuple[float, float] = _SI_RIPPLE
    """Firing-ripple amplitudes (fundamental, 2nd harmonic) relative to the mean τ_i of the
    torque a test-bed shaft transmits, :func:`shaft_ripple_rel` at 2200 rpm: the crank's
    ±100 % (:data:`CRANK_RIPPLE_REL`) through a 15 Hz shaft mode, (0.022, 0.0016), i.e.
    ±2.4 N·m at 2200 rpm. No k = 0.01 s estimator follows a 63–83 Hz ripple, so each one's
    error carries it almost whole. ``TorqueTruth.torque_mean_nm`` is the ripple-free torque."""
    throttle_max_flow_kg_s: float = 0.12  # MAX of TQ (2) [kg/s]
    throttle_leak: float = 0.002  # TC(α) leakage at α = 0 [-]
    pri_coef: float = 9.0  # PRI(p_m) = 1 − exp(c·(p_m/p_a − 1)) [-]
    throttle_limits_deg: tuple[float, float] = (0.5, 90.0)
    throttle_time_constant_s: float = 0.02  # throttle actuator lag [s]
    speed_kp_deg_per_rpm: float = 0.04  # PI speed controller on the throttle
    speed_ki_deg_per_rpm_s: float = 0.08
    load_coef: tuple[float, float] = (30.0, 12.0)
    """Dyno τ_l = c0 + c2·(N/1000)² [N·m, N·m/krpm²]: 88 N·m at 2200 rpm."""
    profile_times_s: tuple[float, ...] = (0.0, 4.0, 12.0, 14.0)  # TQ §VI
    profile_speeds_rpm: tuple[float, ...] = (2200.0, 2500.0, 2200.0, 1900.0)  # TQ §VI
    speed_ramp_s: float = 0.0
    """Each set-point change is a linear ramp of this length [s]; 0 = the steps of TQ §VI."""
    default_duration_s: float = 30.0  # TQ §VI: indices over 5–30 s
    speed_noise_std_rpm: float = VARIANCE_20_STD  # TQ §VI w1 = N(0, 20), read as variance
    load_noise_std_nm: float = VARIANCE_20_STD  # TQ §VI w2 = N(0, 20), read as variance
    air_noise_std_kg_s: float = 0.0  # TQ adds no noise to ṁ_ai


@dataclass(frozen=True, slots=True)
class DieselRigParams(_EngineParams):
    """Diesel engine on a transient dyno, TQ §VII / Table V (turbocharged 2.0 L, 4 cylinders,
    320 N·m at 1800–2000 rpm). Values not in TQ are plausible for such an engine."""

    inertia_kg_m2: float = 0.25  # engine + dual-mass flywheel [kg·m²]; not in TQ
    displacement_m3: float = 1.998e-3  # TQ Table V: 1998 cc
    manifold_volume_m3: float = 3.0e-3  # intake volume incl. intercooler [m³]
    gas_constant_j_kg_k: float = 287.0
    kappa: float = 1.4
    ambient_temp_k: float = 298.0
    manifold_temp_k: float = 298.0  # intercooled charge [K]; = T_a (see SiEngineParams)
    ambient_pressure_pa: float = 101_325.0
    eta_vol_coef: tuple[float, float, float] = (0.88, 0.03, -0.006)
    fuel_heating_value_j_kg: float = 42.7e6  # diesel LHV [J/kg]
    eta_i_max: float = 0.46
    eta_i_c: float = 0.25
    eta_i_speed_rpm: float = 1000.0
    smoke_lambda: float = 1.25  # λ_min of the smoke limiter [-]
    stoich_afr: float = 14.5  # L_th of diesel [-]
    friction_coef: tuple[float, float, float] = (12.0, 4.0e-3, 2.5e-6)
    """a0, a1, a2 of TQ (6): τ_f ≈ 30 N·m (FMEP ≈ 1.9 bar) at 2000 rpm."""
    n_cylinders: int = 4  # TQ Table V
    ripple_rel: tuple[float, float] = _RIG_RIPPLE
    """Firing ripple of the torque the rig's shaft transmits, :func:`shaft_ripple_rel` at
    1750 rpm (the middle of the sweep, 58 Hz): (0.035, 0.0025), ±5.3 N·m at 150 N·m τ_i. The
    crank ripple and shaft mode are the SI engine's (a dual-mass flywheel would only lower
    it)."""
    dyno_kp_nm_per_rpm: float = 2.0  # dyno speed PI on τ_l
    dyno_ki_nm_per_rpm_s: float = 20.0
    boost_gain_pa_per_w: float = 0.9  # boost target p_a + g·H_u·ṁ_f [Pa/W]
    boost_max_pa: float = 2.6e5
    turbo_time_constant_s: float = 0.4
    demand_time_constant_s: float = 0.05  # fuel path / ECU torque filter [s]
    sweep_speed_range_rpm: tuple[float, float] = (1000.0, 2500.0)  # TQ §VII
    sweep_freq_hz: tuple[float, float] = (0.03, 0.3)  # chirp start/end [Hz]; not in TQ
    sweep_duration_s: float = 30.0
    demand_times_s: tuple[float, ...] = (
        0.0, 3.0, 3.3, 7.0, 7.2, 10.0, 16.0, 19.0, 19.3, 22.0, 28.0, 30.0,
    )  # fmt: skip
    demand_torques_nm: tuple[float, ...] = (
        80.0, 80.0, 250.0, 250.0, 60.0, 60.0, 280.0, 280.0, 30.0, 30.0, 200.0, 200.0,
    )  # fmt: skip
    """Torque demand [N·m] within TQ §VII's 0–300 N·m: fast steps (0.2–0.3 s) and slow ramps
    (6 s), "slow and fast transient operating conditions" (TQ §VII)."""
    default_duration_s: float = 30.0  # TQ §VII: indices over 5–30 s
    speed_noise_std_rpm: float = encoder_speed_noise_std_rpm()
    """Test-bed speed noise [rpm]: TQ §VII adds none (its data carry "real ... measurement
    inaccuracies"), so the dyno's speed channel is modelled as a 1024-line quadrature encoder
    counted over each 1 ms sample, :func:`encoder_speed_noise_std_rpm`: one count is 14.6 rpm,
    σ = 4.23 rpm (white, uniform-quantisation equivalent)."""
    load_noise_std_nm: float = load_cell_noise_std_nm()
    """Load-torque noise [N·m]: a 500 N·m torque measurement of accuracy class 0.1 %,
    :func:`load_cell_noise_std_nm`, σ = 0.5 N·m."""
    air_noise_std_kg_s: float = 0.0


def si_coefficients(p: SiEngineParams) -> np.ndarray:
    """Pack :class:`SiEngineParams` into the kernel coefficient vector (``kp.C_*`` indices)."""
    c = _common_coefficients(p, kp.N_SI_COEF, p.lambda_ratio)
    c[kp.C_KP] = p.speed_kp_deg_per_rpm
    c[kp.C_KI] = p.speed_ki_deg_per_rpm_s
    c[kp.C_MAX] = p.throttle_max_flow_kg_s
    c[kp.C_TC_LEAK] = p.throttle_leak
    c[kp.C_PRI_C] = p.pri_coef
    c[kp.C_ALPHA_MIN], c[kp.C_ALPHA_MAX] = p.throttle_limits_deg
    c[kp.C_TAU_THR] = p.throttle_time_constant_s
    c[kp.C_LOAD_C0], c[kp.C_LOAD_C2] = p.load_coef
    return c


def rig_coefficients(p: DieselRigParams) -> np.ndarray:
    """Pack :class:`DieselRigParams` into the kernel coefficient vector."""
    c = _common_coefficients(p, kp.N_RIG_COEF, p.smoke_lambda)
    c[kp.C_KP] = p.dyno_kp_nm_per_rpm
    c[kp.C_KI] = p.dyno_ki_nm_per_rpm_s
    c[kp.C_BOOST_GAIN] = p.boost_gain_pa_per_w
    c[kp.C_P_MAX] = p.boost_max_pa
    c[kp.C_TAU_TURBO] = p.turbo_time_constant_s
    c[kp.C_TAU_DEMAND] = p.demand_time_constant_s
    n_lo, n_hi = p.sweep_speed_range_rpm
    c[kp.C_N_MID] = 0.5 * (n_lo + n_hi)
    c[kp.C_N_AMP] = 0.5 * (n_hi - n_lo)
    c[kp.C_F0], c[kp.C_F1] = p.sweep_freq_hz
    c[kp.C_T_SWEEP] = p.sweep_duration_s
    return c


def _common_coefficients(
    p: SiEngineParams | DieselRigParams, size: int, lambda_ratio: float
) -> np.ndarray:
    c = np.zeros(size)
    c[kp.C_J] = p.J_nm_s_per_rpm
    c[kp.C_VD] = p.displacement_m3
    c[kp.C_VM] = p.manifold_volume_m3
    c[kp.C_R] = p.gas_constant_j_kg_k
    c[kp.C_KAPPA] = p.kappa
    c[kp.C_TA] = p.ambient_temp_k
    c[kp.C_TM] = p.manifold_temp_k
    c[kp.C_PA] = p.ambient_pressure_pa
    c[kp.C_EV0], c[kp.C_EV1], c[kp.C_EV2] = p.eta_vol_coef
    c[kp.C_HU] = p.fuel_heating_value_j_kg
    c[kp.C_ETA_MAX] = p.eta_i_max
    c[kp.C_ETA_C] = p.eta_i_c
    c[kp.C_ETA_NC] = p.eta_i_speed_rpm
    c[kp.C_LAMBDA] = lambda_ratio
    c[kp.C_LTH] = p.stoich_afr
    c[kp.C_A0], c[kp.C_A1], c[kp.C_A2] = p.friction_coef
    c[kp.C_NCYL] = p.n_cylinders
    c[kp.C_R1], c[kp.C_R2] = p.ripple_rel
    return c


def validate_params(p: SiEngineParams | DieselRigParams) -> None:
    """Check the fields both parameter sets share (a :class:`ConfigError` naming the field)."""
    for name in (
        "inertia_kg_m2",
        "displacement_m3",
        "manifold_volume_m3",
        "gas_constant_j_kg_k",
        "kappa",
        "ambient_temp_k",
        "manifold_temp_k",
        "ambient_pressure_pa",
        "fuel_heating_value_j_kg",
        "eta_i_max",
        "eta_i_speed_rpm",
        "stoich_afr",
        "default_duration_s",
    ):
        require_positive(name, getattr(p, name))
    if not isinstance(p.n_cylinders, int) or p.n_cylinders < 1:
        raise ConfigError(f"n_cylinders must be a positive integer, got {p.n_cylinders!r}")
    r1, r2 = p.ripple_rel
    if not (r1 >= 0 and r2 >= 0 and r1 + r2 <= 2.0):
        raise ConfigError(f"ripple_rel must be non-negative and sum to ≤ 2, got {p.ripple_rel}")
    for name in ("speed_noise_std_rpm", "load_noise_std_nm", "air_noise_std_kg_s"):
        v = getattr(p, name)
        if not (math.isfinite(v) and v >= 0):
            raise ConfigError(f"{name} must be a finite value ≥ 0, got {v!r}")


def require_positive(name: str, value: float) -> None:
    """A :class:`ConfigError` unless ``value`` is a finite number > 0."""
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{name} must be a finite positive number, got {value!r}")
