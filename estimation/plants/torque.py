"""Engine torque ground truth: SI mean value engine and a diesel dynamometer rig.

Source: Na, Chen, Herrmann, Burke, Brace, *Vehicle engine torque estimation via unknown input
observer and adaptive parameter estimation*, IEEE TVT 2018 (``papers/
torque-uio-adaptive-estimation.md``, "TQ"); ALGORITHMS.md §5 and §6. Kernels:
:mod:`estimation.kernels.torque_plant`.

SI engine (TQ §II, (1)–(8); scenario of TQ §VI)
-----------------------------------------------
Units: ``p_m`` Pa, ``T`` K, flows kg/s, ``N`` rpm, torque N·m::

    ṗ_m  = κR/V_m·(ṁ_ai·T_a − ṁ_ao·T_m)                                    TQ (1)
    ṁ_ai = MAX·TC(α)·PRI(p_m),  TC = 1 − cos α + leak,
           PRI = 1 − exp(c_pri·(p_m/p_a − 1))                               TQ (2)
    ṁ_ao = √(T_m/T_a)·V_d·η_vol(N)·N·p_m/(120·R·T_m)                        TQ (3)
    ṁ_f  = ṁ_ao/(λ·L_th)                                                    TQ (4)
    τ_i  = H_u·η_i(N)·ṁ_f/(2πN/60) · g(ψ)                                   TQ (5) × ripple
    τ_f  = a0 + a1·N + a2·N²                                                TQ (6)
    τ_e  = τ_i − τ_f                                                        TQ (7)
    J·Ṅ  = τ_e − τ_l,   J = J_kg_m2·2π/60  [N·m·s/rpm]                       TQ (8)

TQ gives the *structure* only: the shapes of TC, PRI, η_vol(N) and η_i(N) ("exponentially
dependent on N", TQ §II-C) are our choices, documented on :class:`SiEngineParams`.
``g(ψ) = 1 + r1·cos ψ + r2·cos 2ψ`` with ``ψ = crank·n_cyl/2`` is the per-cylinder firing
ripple (cycle mean 1, so the cycle-mean torque is the mean value model); a 4-stroke engine
fires ``n_cyl/2`` times per revolution, i.e. at ``f = N·n_cyl/120`` Hz (73 Hz at 2200 rpm).

Scenario (TQ §VI): "the throttle angle is driven by a feedback controller to cope with the
load demand" along a predefined speed profile ``N = 2200 → 2500 → 2200 → 1900 rpm at t = 0, 4,
12 and 14 s``. Here a PI controller (with anti-windup and a first-order throttle actuator)
sets α from ``N_ref − N``; the dynamometer applies a road-load-like torque
``τ_l = c0 + c2·(N/1000)²``. ``N_ref`` steps as TQ says (or ramps over ``speed_ramp_s``).

Diesel rig (TQ §VII)
--------------------
Turbocharged 2.0 L four-cylinder diesel (TQ Table V) on a transient dynamometer. The dyno
holds the speed on a sine sweep between 1000 and 2500 rpm (PI on ``N − N_ref`` acting on
``τ_l``); the engine follows a torque demand between 0 and 300 N·m with slow ramps and fast
steps. Fuel from TQ (5) inverted for ``τ_i = demand + τ_f``, limited by a smoke limit
``ṁ_f ≤ ṁ_ao/(λ_min·L_th)``; boost pressure ``p_m`` lags (turbo lag) towards
``p_a + g·H_u·ṁ_f``; ``ṁ_ao`` by TQ (3); the MAF flow ``ṁ_ai`` by TQ (1) solved for it. TQ
shows the rig data only in Fig. 8, so the profiles are reconstructions, not copies.

Truth of TQ (41)
----------------
TQ (41) writes ``τ_e = Φ·Θ(t)``, ``Φ = [N, ṁ_ai]``, ``Θ = [θ1, θ2]ᵀ`` but does not say how
``τ_e`` splits. We split it along the model terms: friction depends on speed only (TQ (6)),
combustion on the air (TQ (4)–(5))::

    θ1(t) = −τ_f(N)/N            [N·m/rpm]       = −(a0/N + a1 + a2·N)
    θ2(t) =  τ_i(t)/ṁ_ai(t)      [N·m/(kg/s)]    = H_u·η_i(N)/(λ·L_th·2πN/60) · (ṁ_ao/ṁ_ai) · g(ψ)

so ``τ_e = θ1·N + θ2·ṁ_ai`` exactly (round-off) with the *true* ``N`` and ``ṁ_ai``. θ2 carries
the manifold filling ``ṁ_ao/ṁ_ai`` (≠ 1 in transients) and the firing ripple, which is why
Θ is fast time-varying (TQ §V).

Measurements (TQ §VI)
---------------------
``N`` and ``τ_l`` plus white Gaussian noise; TQ writes ``w1 = N(0, 20)``, ``w2 = N(0, 20)``
without saying whether 20 is the variance or the standard deviation. We read the usual
``N(μ, σ²)`` convention — variance 20, σ = √20 ≈ 4.47 rpm and N·m. Table III confirms it:
dirty differentiation passes w2 unfiltered where the UIO filters it, which adds ≈ 0.95·σ² to
its error variance (TQ (30), (37)); the table's gap is 4.90² − 2.81² = 16 N·m² (σ = 20 would
give ≈ 380). Both are one field away (``speed_noise_std_rpm``). The rig (TQ §VII) has no
artificial noise; its defaults are bounded by Table VI (see :class:`DieselRigParams`). TQ adds
no noise to ``ṁ_ai``; ``air_noise_std_kg_s`` defaults to 0. TQ does not state its data rate;
we output 1 kHz (``k = 0.01 s`` needs ``Ts ≪ k``) from a 10 kHz RK4 integration, by taking
every ``internal_rate_hz/rate_hz``-th state (point sampling: truth identities hold per sample).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from estimation.errors import ConfigError
from estimation.kernels import torque_plant as kp
from estimation.signals import Signals

SPEED_CHANNEL = "speed_rpm"
LOAD_CHANNEL = "load_torque_nm"
AIR_CHANNEL = "air_mass_flow_kg_s"
THROTTLE_CHANNEL = "throttle_deg"
MANIFOLD_CHANNEL = "manifold_pressure_pa"
SPEED_REF_CHANNEL = "speed_setpoint_rpm"
DEMAND_CHANNEL = "torque_demand_nm"

VARIANCE_20_STD: float = math.sqrt(20.0)
"""σ of TQ §VI's ``N(0, 20)`` read as variance 20 (see module docstring)."""


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

    inertia_kg_m2: float = 0.05
    """Crank-train inertia [kg·m²]. TQ gives no value, but Table III bounds it: the UIO passes
    the speed noise as ``J/k·(w1 − w1f)`` (TQ (30)), SD ``≈ (J/k)·σ_N·√(1 + ρ)``,
    ``ρ = (1 − a)/(1 + a) ≈ 0.05`` at 1 kHz; with §VI's ``σ_N = √20`` rpm the table's UIO SD
    of 2.81 N·m needs ``J/k ≤ 0.6`` N·m/rpm, i.e. an inertia ≤ 0.057 kg·m² (an engine without a
    heavy flywheel). A typical engine + flywheel, 0.15 kg·m², puts the UIO's noise floor alone
    at 7.0 N·m."""
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
    ripple_rel: tuple[float, float] = (0.02, 0.005)
    """Firing-ripple amplitudes (fundamental, 2nd harmonic) relative to the mean τ_i (±2.3 N·m
    at 2200 rpm). No k = 0.01 s estimator follows a 63–83 Hz ripple: each one's error carries
    it almost whole (here ≈ 1.5 N·m RMS). TQ Table IV's smallest SD, 1.82 N·m ((54), κ = 0.1),
    bounds that floor in the paper's reference torque, so real gas-torque swings (±100 %) are
    not what TQ scored; (0.1, 0.03) alone gave a 7.5 N·m floor. ``TorqueTruth.torque_mean_nm``
    is the ripple-free torque."""
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
    ripple_rel: tuple[float, float] = (0.01, 0.003)
    """Firing ripple of the scored torque (±1.5 N·m at 150 N·m τ_i). TQ Table VII's smallest
    SD, 1.30 N·m ((50), κ = 0.1), bounds the part of the rig's reference torque no k = 0.01 s
    estimator follows; (0.25, 0.08) alone gave a 35 N·m floor, which also let the dyno's
    speed loop feed the ripple into τ_l and hand dirty differentiation a spurious edge."""
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
    speed_noise_std_rpm: float = 1.0
    """Test-bed speed noise [rpm]. TQ §VII adds none (its data carry "real ... measurement
    inaccuracies"); Table VI bounds it: the UIO's SD of 2.91 N·m needs ``(J/k)·σ_N ≲ 2.8``
    N·m, i.e. ``σ_N ≲ 1.1`` rpm with this inertia (see ``SiEngineParams.inertia_kg_m2``)."""
    load_noise_std_nm: float = VARIANCE_20_STD
    """Load-cell noise [N·m]. Table VI's dirty − UIO variance gap, 4.84² − 2.91² = 15 N·m², is
    what a white load noise of variance σ² adds to dirty differentiation (≈ 0.95·σ²: TQ (37)
    passes w2 unfiltered, (30) filters it): σ² ≈ 16, close to §VI's 20, which is kept."""
    air_noise_std_kg_s: float = 0.0


@dataclass(frozen=True, slots=True)
class TorqueTruth:
    """True plant trajectories on the output time base (all ``(n,)`` float64 arrays).

    ``τ_e = θ1·N + θ2·ṁ_ai`` holds per sample with ``speed_rpm`` and ``air_mass_flow_kg_s``
    (TQ (41)); ``J_nm_s_per_rpm`` is the J of TQ (8) in the units of these arrays.
    """

    time_s: np.ndarray
    torque_nm: np.ndarray  # τ_e with firing ripple, TQ (7)
    torque_mean_nm: np.ndarray  # cycle-mean τ_e (mean value model)
    indicated_torque_nm: np.ndarray  # τ_i, TQ (5)
    friction_torque_nm: np.ndarray  # τ_f, TQ (6)
    load_torque_nm: np.ndarray  # τ_l, TQ (8)
    speed_rpm: np.ndarray  # N
    speed_setpoint_rpm: np.ndarray  # N_ref
    air_mass_flow_kg_s: np.ndarray  # ṁ_ai, TQ (2) (SI) / TQ (1) (rig)
    cylinder_air_flow_kg_s: np.ndarray  # ṁ_ao, TQ (3)
    fuel_mass_flow_kg_s: np.ndarray  # ṁ_f, TQ (4)
    manifold_pressure_pa: np.ndarray  # p_m, TQ (1)
    theta1: np.ndarray  # θ1 = −τ_f/N  [N·m/rpm], TQ (41)
    theta2: np.ndarray  # θ2 = τ_i/ṁ_ai [N·m/(kg/s)], TQ (41)
    firing_frequency_hz: np.ndarray  # N·n_cyl/120
    J_nm_s_per_rpm: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: arrays as lists of floats, scalars as floats."""
        d: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            d[f.name] = v.tolist() if isinstance(v, np.ndarray) else float(v)
        return d


# --- public API ---------------------------------------------------------------------------
def simulate_si_torque(
    *,
    seed: int,
    duration_s: float | None = None,
    rate_hz: float = 1000.0,
    internal_rate_hz: float = 10_000.0,
    params: SiEngineParams | None = None,
) -> tuple[Signals, TorqueTruth]:
    """Simulate the SI engine of TQ §VI (speed profile 2200→2500→2200→1900 rpm).

    Returns measured :class:`Signals` — ``speed_rpm`` (+ noise w1), ``load_torque_nm``
    (+ noise w2), ``air_mass_flow_kg_s`` (ṁ_ai, + optional noise), and noise-free
    ``throttle_deg``, ``manifold_pressure_pa``, ``speed_setpoint_rpm`` — and the
    :class:`TorqueTruth`. Noise from ``np.random.default_rng(seed)``, drawn in that channel
    order. Starts in steady state at the first set-point.
    """
    p = SiEngineParams() if params is None else params
    _validate_common(p)
    times = np.asarray(p.profile_times_s, dtype=np.float64)
    speeds = np.asarray(p.profile_speeds_rpm, dtype=np.float64)
    if times.size == 0 or times.size != speeds.size:
        raise ConfigError(
            f"profile_times_s and profile_speeds_rpm must be non-empty and equally long, got "
            f"{times.size} and {speeds.size}"
        )
    if times[0] != 0.0 or np.any(np.diff(times) <= 0):
        raise ConfigError(f"profile_times_s must start at 0 and increase, got {p.profile_times_s}")
    if np.any(speeds <= 0):
        raise ConfigError(f"profile_speeds_rpm must be positive, got {p.profile_speeds_rpm}")
    gaps = np.diff(times)
    if not (p.speed_ramp_s >= 0 and math.isfinite(p.speed_ramp_s)) or (
        gaps.size and p.speed_ramp_s >= gaps.min()
    ):
        raise ConfigError(
            f"speed_ramp_s must be ≥ 0 and shorter than the shortest profile step "
            f"({gaps.min() if gaps.size else math.inf:g} s), got {p.speed_ramp_s!r}"
        )
    lo, hi = p.throttle_limits_deg
    if not 0.0 <= lo < hi <= 90.0:
        raise ConfigError(f"throttle_limits_deg must satisfy 0 ≤ lo < hi ≤ 90, got {(lo, hi)}")
    for name in ("throttle_max_flow_kg_s", "pri_coef", "throttle_time_constant_s"):
        _require_positive(name, getattr(p, name))
    dt, decimation, n_out = _time_base(
        p.default_duration_s if duration_s is None else duration_s, rate_hz, internal_rate_hz
    )

    coef = si_coefficients(p)
    ref_t = [0.0]
    ref_n = [speeds[0]]
    for ti, n_prev, n_new in zip(times[1:], speeds[:-1], speeds[1:], strict=True):
        ref_t += [float(ti), float(ti) + p.speed_ramp_s]
        ref_n += [float(n_prev), float(n_new)]
    ref_time_s = np.asarray(ref_t, dtype=np.float64)
    ref_speed_rpm = np.asarray(ref_n, dtype=np.float64)

    n0 = float(speeds[0])
    alpha0 = _si_throttle_for_load(p, coef, n0)
    p_m0 = kp.si_manifold_equilibrium_pa(n0, alpha0, coef)
    x0 = np.array([p_m0, n0, 0.0, alpha0, alpha0])
    out = _integrate(kp.PLANT_SI, coef, ref_time_s, ref_speed_rpm, x0, dt, decimation, n_out)
    extra = {
        THROTTLE_CHANNEL: (out[:, kp.OUT_ACTUATOR], "deg"),
        MANIFOLD_CHANNEL: (out[:, kp.OUT_MANIFOLD_PA], "Pa"),
        SPEED_REF_CHANNEL: (out[:, kp.OUT_SPEED_REF_RPM], "rpm"),
    }
    return _package(out, rate_hz, n_out, p, seed, extra)


def simulate_torque_rig(
    *,
    seed: int,
    duration_s: float | None = None,
    rate_hz: float = 1000.0,
    internal_rate_hz: float = 10_000.0,
    params: DieselRigParams | None = None,
) -> tuple[Signals, TorqueTruth]:
    """Simulate the diesel dynamometer rig of TQ §VII (speed sweep 1000–2500 rpm, demand
    0–300 N·m).

    Returns :class:`Signals` with ``speed_rpm``, ``load_torque_nm`` (dyno load cell),
    ``air_mass_flow_kg_s`` (MAF, ṁ_ai) with noise as in :func:`simulate_si_torque`, and
    noise-free ``manifold_pressure_pa``, ``speed_setpoint_rpm``, ``torque_demand_nm``; and
    the :class:`TorqueTruth`. Starts in steady state at ``N_ref(0)`` and the first demand.
    """
    p = DieselRigParams() if params is None else params
    _validate_common(p)
    n_lo, n_hi = p.sweep_speed_range_rpm
    if not 0.0 < n_lo < n_hi:
        raise ConfigError(f"sweep_speed_range_rpm must satisfy 0 < lo < hi, got {(n_lo, n_hi)}")
    f0, f1 = p.sweep_freq_hz
    if f0 < 0.0 or f1 < 0.0:
        raise ConfigError(f"sweep_freq_hz must be non-negative, got {(f0, f1)}")
    times = np.asarray(p.demand_times_s, dtype=np.float64)
    torques = np.asarray(p.demand_torques_nm, dtype=np.float64)
    if times.size == 0 or times.size != torques.size:
        raise ConfigError(
            f"demand_times_s and demand_torques_nm must be non-empty and equally long, got "
            f"{times.size} and {torques.size}"
        )
    if np.any(np.diff(times) <= 0):
        raise ConfigError(f"demand_times_s must increase, got {p.demand_times_s}")
    for name in (
        "smoke_lambda",
        "boost_gain_pa_per_w",
        "turbo_time_constant_s",
        "demand_time_constant_s",
        "sweep_duration_s",
        "dyno_kp_nm_per_rpm",
    ):
        _require_positive(name, getattr(p, name))
    if p.boost_max_pa <= p.ambient_pressure_pa:
        raise ConfigError(f"boost_max_pa must exceed ambient pressure, got {p.boost_max_pa!r}")
    dt, decimation, n_out = _time_base(
        p.default_duration_s if duration_s is None else duration_s, rate_hz, internal_rate_hz
    )

    coef = rig_coefficients(p)
    n0 = kp.rig_speed_ref(0.0, coef)
    d0 = float(torques[0])
    p_m0 = kp.rig_boost_equilibrium_pa(n0, d0, coef)
    m_f0 = kp.rig_fuel(n0, d0, p_m0, coef)
    tau_e0 = kp.indicated_torque_mean(n0, m_f0, coef) - kp.friction_torque(n0, coef)
    x0 = np.array([p_m0, n0, 0.0, tau_e0, d0])
    out = _integrate(kp.PLANT_RIG, coef, times, torques, x0, dt, decimation, n_out)
    extra = {
        MANIFOLD_CHANNEL: (out[:, kp.OUT_MANIFOLD_PA], "Pa"),
        SPEED_REF_CHANNEL: (out[:, kp.OUT_SPEED_REF_RPM], "rpm"),
        DEMAND_CHANNEL: (out[:, kp.OUT_ACTUATOR], "N·m"),
    }
    return _package(out, rate_hz, n_out, p, seed, extra)


def si_steady_torque_nm(params: SiEngineParams, *, speed_rpm: float, throttle_deg: float) -> float:
    """Cycle-mean effective torque τ_e [N·m] with the manifold in equilibrium (ṗ_m = 0 in
    TQ (1)) at fixed speed and throttle angle — the static map of the SI plant."""
    if speed_rpm <= 0:
        raise ConfigError(f"speed_rpm must be positive, got {speed_rpm!r}")
    if not 0.0 <= throttle_deg <= 90.0:
        raise ConfigError(f"throttle_deg must be in [0, 90], got {throttle_deg!r}")
    return float(
        kp.si_steady_torque_nm(float(speed_rpm), float(throttle_deg), si_coefficients(params))
    )


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


# --- helpers ------------------------------------------------------------------------------
_TRUTH_COLUMNS: dict[str, int] = {
    "torque_nm": kp.OUT_TORQUE_NM,
    "torque_mean_nm": kp.OUT_TORQUE_MEAN_NM,
    "indicated_torque_nm": kp.OUT_INDICATED_NM,
    "friction_torque_nm": kp.OUT_FRICTION_NM,
    "load_torque_nm": kp.OUT_LOAD_NM,
    "speed_rpm": kp.OUT_SPEED_RPM,
    "speed_setpoint_rpm": kp.OUT_SPEED_REF_RPM,
    "air_mass_flow_kg_s": kp.OUT_AIR_IN_KG_S,
    "cylinder_air_flow_kg_s": kp.OUT_AIR_CYL_KG_S,
    "fuel_mass_flow_kg_s": kp.OUT_FUEL_KG_S,
    "manifold_pressure_pa": kp.OUT_MANIFOLD_PA,
    "theta1": kp.OUT_THETA1,
    "theta2": kp.OUT_THETA2,
    "firing_frequency_hz": kp.OUT_FIRING_HZ,
}


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


def _validate_common(p: SiEngineParams | DieselRigParams) -> None:
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
        _require_positive(name, getattr(p, name))
    if not isinstance(p.n_cylinders, int) or p.n_cylinders < 1:
        raise ConfigError(f"n_cylinders must be a positive integer, got {p.n_cylinders!r}")
    r1, r2 = p.ripple_rel
    if not (r1 >= 0 and r2 >= 0 and r1 + r2 <= 2.0):
        raise ConfigError(f"ripple_rel must be non-negative and sum to ≤ 2, got {p.ripple_rel}")
    for name in ("speed_noise_std_rpm", "load_noise_std_nm", "air_noise_std_kg_s"):
        v = getattr(p, name)
        if not (math.isfinite(v) and v >= 0):
            raise ConfigError(f"{name} must be a finite value ≥ 0, got {v!r}")


def _require_positive(name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{name} must be a finite positive number, got {value!r}")


def _time_base(
    duration_s: float, rate_hz: float, internal_rate_hz: float
) -> tuple[float, int, int]:
    _require_positive("duration_s", duration_s)
    _require_positive("rate_hz", rate_hz)
    _require_positive("internal_rate_hz", internal_rate_hz)
    ratio = internal_rate_hz / rate_hz
    decimation = round(ratio)
    if decimation < 1 or abs(ratio - decimation) > 1e-9 * ratio:
        raise ConfigError(
            f"internal_rate_hz ({internal_rate_hz:g}) must be an integer multiple of rate_hz "
            f"({rate_hz:g})"
        )
    if internal_rate_hz < 1000.0:
        raise ConfigError(
            f"internal_rate_hz must be ≥ 1000 to resolve the firing ripple, got "
            f"{internal_rate_hz:g}"
        )
    n_out = math.floor(duration_s * rate_hz + 1e-9) + 1
    if n_out < 2:
        raise ConfigError(
            f"duration_s={duration_s:g} gives fewer than two samples at {rate_hz:g} Hz"
        )
    return 1.0 / internal_rate_hz, decimation, n_out


def _si_throttle_for_load(p: SiEngineParams, coef: np.ndarray, n_rpm: float) -> float:
    """Throttle angle whose steady torque equals the dyno load at ``n_rpm`` (bisection on the
    monotone static map)."""
    nk = n_rpm / 1000.0
    load = p.load_coef[0] + p.load_coef[1] * nk * nk
    lo, hi = p.throttle_limits_deg
    if kp.si_steady_torque_nm(n_rpm, hi, coef) < load:
        raise ConfigError(
            f"load {load:.1f} N·m at {n_rpm:g} rpm exceeds the engine's full-throttle torque "
            f"{kp.si_steady_torque_nm(n_rpm, hi, coef):.1f} N·m; reduce load_coef"
        )
    if kp.si_steady_torque_nm(n_rpm, lo, coef) > load:
        raise ConfigError(
            f"load {load:.1f} N·m at {n_rpm:g} rpm is below the closed-throttle torque; "
            f"raise load_coef"
        )
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if kp.si_steady_torque_nm(n_rpm, mid, coef) < load:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _integrate(
    plant: int,
    coef: np.ndarray,
    table_x: np.ndarray,
    table_y: np.ndarray,
    x0: np.ndarray,
    dt: float,
    decimation: int,
    n_out: int,
) -> np.ndarray:
    """Run :func:`~estimation.kernels.torque_plant.torque_rk4_kernel`; ``(n_out, N_OUT)``."""
    out = np.empty((n_out, kp.N_OUT))
    kp.torque_rk4_kernel(plant, coef, table_x, table_y, x0, dt, decimation, out)
    _require_finite_out(out)
    return out


def _require_finite_out(out: np.ndarray) -> None:
    if not np.all(np.isfinite(out)):
        k, col = np.argwhere(~np.isfinite(out))[0]
        raise ConfigError(
            f"the plant diverged (non-finite output column {col} at sample {k}); check the "
            f"parameters (controller gains, loads) for feasibility"
        )


def _package(
    out: np.ndarray,
    rate_hz: float,
    n_out: int,
    p: SiEngineParams | DieselRigParams,
    seed: int,
    extra: dict[str, tuple[np.ndarray, str]],
) -> tuple[Signals, TorqueTruth]:
    time_s = np.arange(n_out, dtype=np.float64) / rate_hz
    col = {name: np.ascontiguousarray(out[:, i]) for name, i in _TRUTH_COLUMNS.items()}
    truth = TorqueTruth(time_s=time_s, J_nm_s_per_rpm=p.J_nm_s_per_rpm, **col)
    rng = np.random.default_rng(seed)
    speed = col["speed_rpm"] + p.speed_noise_std_rpm * rng.standard_normal(n_out)
    load = col["load_torque_nm"] + p.load_noise_std_nm * rng.standard_normal(n_out)
    air = col["air_mass_flow_kg_s"] + p.air_noise_std_kg_s * rng.standard_normal(n_out)
    channels = {SPEED_CHANNEL: speed, LOAD_CHANNEL: load, AIR_CHANNEL: air}
    units = {SPEED_CHANNEL: "rpm", LOAD_CHANNEL: "N·m", AIR_CHANNEL: "kg/s"}
    for name, (values, unit) in extra.items():
        channels[name] = values
        units[name] = unit
    return Signals(time_s, channels, units), truth
