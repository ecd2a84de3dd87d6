"""Engine torque ground truth: SI mean value engine and a diesel dynamometer rig.

Source: Na, Chen, Herrmann, Burke, Brace, *Vehicle engine torque estimation via unknown input
observer and adaptive parameter estimation*, IEEE TVT 2018 (``papers/
torque-uio-adaptive-estimation.md``, "TQ"); docs/algorithms.md §5 and §6. Parameters:
:mod:`estimation.plants.torque_params`; kernels: :mod:`estimation.kernels.torque_plant`.

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
``N(μ, σ²)`` convention — variance 20, σ = √20 ≈ 4.47 rpm and N·m; the other reading is one
field away (``speed_noise_std_rpm``, ``load_noise_std_nm``). The rig (TQ §VII) has no
artificial noise; its defaults are a test bed's sensors — a 1024-line encoder counted per
1 ms sample and a 0.1 %-class torque measurement (see :class:`DieselRigParams`). TQ adds
no noise to ``ṁ_ai``; ``air_noise_std_kg_s`` defaults to 0. TQ does not state its data rate;
we output 1 kHz (``k = 0.01 s`` needs ``Ts ≪ k``) from a 10 kHz RK4 integration, by taking
every ``internal_rate_hz/rate_hz``-th state (point sampling: truth identities hold per sample).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from estimation.errors import ConfigError
from estimation.kernels import torque_plant as kp
from estimation.plants import sampling
from estimation.plants.torque_params import (
    DieselRigParams,
    SiEngineParams,
    require_positive,
    rig_coefficients,
    si_coefficients,
    validate_params,
)
from estimation.signals import Signals
from estimation.torque.channels import AIR_CHANNEL, LOAD_CHANNEL, SPEED_CHANNEL

THROTTLE_CHANNEL = "throttle_deg"
MANIFOLD_CHANNEL = "manifold_pressure_pa"
SPEED_REF_CHANNEL = "speed_setpoint_rpm"
DEMAND_CHANNEL = "torque_demand_nm"


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
TRANSIENT_24S_S: float = 24.0
TRANSIENT_24S_RPM: float = 2200.0
"""The set-point step of ``transient_24s`` [s, rpm]: 1900 → 2200 rpm, the size of TQ §VI's
other steps (the paper shows the transient, not its size)."""


def simulate_si_torque(
    *,
    seed: int,
    duration_s: float | None = None,
    rate_hz: float = 1000.0,
    internal_rate_hz: float = 10_000.0,
    params: SiEngineParams | None = None,
    transient_24s: bool = False,
) -> tuple[Signals, TorqueTruth]:
    """Simulate the SI engine of TQ §VI (speed profile 2200→2500→2200→1900 rpm).

    ``transient_24s``: add a set-point step to :data:`TRANSIENT_24S_RPM` at 24 s. TQ's
    estimation figures (§VI) show a transient at 24 s that its stated profile (steps at 0, 4,
    12, 14 s) lacks; its size is not stated, so the step repeats the profile's 300 rpm.

    Returns measured :class:`Signals` — ``speed_rpm`` (+ noise w1), ``load_torque_nm``
    (+ noise w2), ``air_mass_flow_kg_s`` (ṁ_ai, + optional noise), and noise-free
    ``throttle_deg``, ``manifold_pressure_pa``, ``speed_setpoint_rpm`` — and the
    :class:`TorqueTruth`. Noise from ``np.random.default_rng(seed)``, drawn in that channel
    order. Starts in steady state at the first set-point.
    """
    p = SiEngineParams() if params is None else params
    validate_params(p)
    times, speeds = _schedule(p, "profile_times_s", "profile_speeds_rpm")
    if transient_24s:
        if times[-1] >= TRANSIENT_24S_S:
            raise ConfigError(
                f"transient_24s needs a profile that ends before {TRANSIENT_24S_S:g} s, got "
                f"{p.profile_times_s}"
            )
        times = np.append(times, TRANSIENT_24S_S)
        speeds = np.append(speeds, TRANSIENT_24S_RPM)
    if times[0] != 0.0:
        raise ConfigError(f"profile_times_s must start at 0, got {p.profile_times_s}")
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
        require_positive(name, getattr(p, name))
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
    validate_params(p)
    n_lo, n_hi = p.sweep_speed_range_rpm
    if not 0.0 < n_lo < n_hi:
        raise ConfigError(f"sweep_speed_range_rpm must satisfy 0 < lo < hi, got {(n_lo, n_hi)}")
    f0, f1 = p.sweep_freq_hz
    if f0 < 0.0 or f1 < 0.0:
        raise ConfigError(f"sweep_freq_hz must be non-negative, got {(f0, f1)}")
    times, torques = _schedule(p, "demand_times_s", "demand_torques_nm")
    for name in (
        "smoke_lambda",
        "boost_gain_pa_per_w",
        "turbo_time_constant_s",
        "demand_time_constant_s",
        "sweep_duration_s",
        "dyno_kp_nm_per_rpm",
    ):
        require_positive(name, getattr(p, name))
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


def _schedule(
    p: SiEngineParams | DieselRigParams, times_field: str, values_field: str
) -> tuple[np.ndarray, np.ndarray]:
    """The breakpoints ``(times [s], values)`` of a set-point schedule of ``p``, checked:
    non-empty, equally long, times strictly increasing."""
    times = np.asarray(getattr(p, times_field), dtype=np.float64)
    values = np.asarray(getattr(p, values_field), dtype=np.float64)
    if times.size == 0 or times.size != values.size:
        raise ConfigError(
            f"{times_field} and {values_field} must be non-empty and equally long, got "
            f"{times.size} and {values.size}"
        )
    if np.any(np.diff(times) <= 0):
        raise ConfigError(f"{times_field} must increase, got {getattr(p, times_field)}")
    return times, values


def _time_base(
    duration_s: float, rate_hz: float, internal_rate_hz: float
) -> tuple[float, int, int]:
    require_positive("duration_s", duration_s)
    require_positive("rate_hz", rate_hz)
    require_positive("internal_rate_hz", internal_rate_hz)
    n_sub = sampling.decimation(rate_hz, internal_rate_hz)
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
    return 1.0 / internal_rate_hz, n_sub, n_out


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
