"""Vehicle, gearbox and driver model: cycles → engine operating points (docs/algorithms.md §6).

A *backward* (speed-following) model: the driver follows the cycle's speed trace exactly, so
the wheel force is computed from the trace and pushed back through the driveline.

1. **Interpolation** to ``rate_hz``: the 1 Hz trace is interpolated with a monotone cubic
   Hermite spline (Fritsch & Carlson 1980, PCHIP) — C¹ speed, continuous acceleration, no
   overshoot (so no negative speeds and exact standstills); the grade linearly.
2. **Road load** (SI units, ``θ = atan(grade_pct/100)``)::

       F = f_rot·m·a + m·g·(c_rr·cos θ·min(v/v_stop, 1) + sin θ) + ½·ρ·c_dA·v²,   T_w = F·r_w

3. **Gearbox and driver** (sequential, numba kernel):

   - neutral (gear 0) below ``v_stop``; engage from neutral when accelerating (the highest
     gear with speed and torque margin, else 1st with clutch slip), or when rolling steadily
     and such a gear exists;
   - up-shift above ``n_up = n_up,light + (n_up,full − n_up,light)·T_d/T_max``, only if the
     next gear keeps ``n ≥ n_down + hysteresis`` and ``T_d ≤ reserve·T_max`` and never while
     decelerating; down-shift below ``n_down`` or when ``T_d > T_max`` (kick-down);
   - these shifts wait ``min_gear_time_s`` after the last one (no hunting); forced up-shift
     above rated speed; declutch (neutral) when braking in 2nd below ``n_down`` or when the
     gear would pull the engine below idle while not accelerating;
   - clutch slip holds the engine at idle when 1st gear would pull it below idle; engine
     speed follows its target (gear speed clipped to [idle, rated]) with a slew-rate limit,
     so shifts are ramps.
4. **Engine** (:class:`DieselEngine`, :mod:`estimation.plants.engine`): demand
   ``T_d = T_w/(i·η)`` when driving, ``T_w·η/i`` on overrun, ``i = i_gear·i_final``.
   Driving: ``T_e = min(T_d, T_max(n))``. Overrun above ``fuel_cut_min_rpm``: fuel cut,
   ``u_δ = 0``, ``T_e = −T_fr(n)`` (motoring, brakes take the rest). Neutral or overrun
   below it: idle governor, ``T_e = 0``. Fuel from the Willans line of
   :meth:`DieselEngine.fuel_mg_per_cycle`.

Engine cycles (WHTC) are denormalised with :func:`denormalise_engine_cycle` (GTR 4 §7.4).
The gearbox kernel (:func:`estimation.kernels.vehicle.gearbox_kernel`) does no validation;
the public functions validate.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimation.cycles.base import Cycle
from estimation.errors import ConfigError, SignalError
from estimation.kernels.vehicle import gearbox_kernel
from estimation.plants.engine import DieselEngine
from estimation.signals import Signals

_G_MS2 = 9.81
_RPM_PER_RAD_S = 30.0 / np.pi


@dataclass(frozen=True, slots=True)
class ShiftStrategy:
    """Driver and gearbox control (see the module docstring for the rules). Speeds in rpm."""

    upshift_light_rpm: float = 2000.0  # up-shift engine speed at zero load
    upshift_full_rpm: float = 3600.0  # … at full load (linear in T_d/T_max between)
    downshift_rpm: float = 1200.0
    hysteresis_rpm: float = 150.0  # next gear must keep n >= downshift + hysteresis
    upshift_torque_reserve: float = 0.85  # next gear must keep T_d <= reserve·T_max
    min_gear_time_s: float = 2.0  # no non-forced shift sooner after the last one
    stop_speed_kmh: float = 0.5  # below: standstill, neutral
    engage_accel_ms2: float = 0.05  # engage a gear from neutral when accelerating above this
    speed_slew_rpm_per_s: float = 3000.0  # engine speed rate limit (clutch engagement, shifts)

    def __post_init__(self) -> None:
        if not (
            0
            < self.downshift_rpm + self.hysteresis_rpm
            < self.upshift_light_rpm
            <= self.upshift_full_rpm
        ):
            raise ConfigError(
                f"need 0 < downshift + hysteresis ({self.downshift_rpm + self.hysteresis_rpm:g}) "
                f"< upshift_light ({self.upshift_light_rpm:g}) <= upshift_full "
                f"({self.upshift_full_rpm:g}) rpm"
            )
        if not 0 < self.upshift_torque_reserve <= 1:
            raise ConfigError(
                f"upshift_torque_reserve must be in (0, 1], got {self.upshift_torque_reserve!r}"
            )
        for name in ("min_gear_time_s", "stop_speed_kmh", "speed_slew_rpm_per_s"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)!r}")


@dataclass(frozen=True, slots=True)
class Vehicle:
    """A light-duty passenger car (≈1.6 t test mass) with a 6-speed manual gearbox.

    ``f_rot`` (``rotating_mass_factor``) lumps wheel, driveline and engine inertia into an
    equivalent mass ``f_rot·m``. ``driveline_efficiency`` η applies gearbox and final drive.
    """

    mass_kg: float = 1600.0
    rotating_mass_factor: float = 1.05
    rolling_resistance: float = 0.010  # c_rr (-)
    drag_area_m2: float = 0.66  # c_d·A (m²)
    air_density_kg_m3: float = 1.2
    wheel_radius_m: float = 0.31
    final_drive_ratio: float = 3.55
    gear_ratios: tuple[float, ...] = (3.82, 2.05, 1.30, 0.96, 0.76, 0.62)
    driveline_efficiency: float = 0.93
    shift: ShiftStrategy = field(default_factory=ShiftStrategy)

    def __post_init__(self) -> None:
        for name in (
            "mass_kg",
            "drag_area_m2",
            "air_density_kg_m3",
            "wheel_radius_m",
            "final_drive_ratio",
        ):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.rotating_mass_factor < 1 or self.rolling_resistance < 0:
            raise ConfigError("need rotating_mass_factor >= 1 and rolling_resistance >= 0")
        if not 0 < self.driveline_efficiency <= 1:
            raise ConfigError(
                f"driveline_efficiency must be in (0, 1], got {self.driveline_efficiency!r}"
            )
        r = np.asarray(self.gear_ratios, dtype=np.float64)
        if r.ndim != 1 or r.size < 1 or np.any(r <= 0) or np.any(np.diff(r) >= 0):
            raise ConfigError(
                f"gear_ratios must be positive and strictly decreasing, got {self.gear_ratios}"
            )

    def overall_ratios(self) -> np.ndarray:
        """``i = i_gear·i_final`` per gear, shape ``(n_gears,)``."""
        return np.asarray(self.gear_ratios, dtype=np.float64) * self.final_drive_ratio


@dataclass(frozen=True, slots=True, eq=False)
class OperatingPoints:
    """Engine operating points on a uniform time base; all arrays ``(n,)`` and read-only.

    ``gear`` is 0 in neutral/idle and for engine cycles (no gearbox); ``vehicle_speed_kmh`` is
    ``None`` for engine cycles.
    """

    time_s: np.ndarray
    speed_rpm: np.ndarray
    torque_nm: np.ndarray
    fuel_mg_per_cycle: np.ndarray
    gear: np.ndarray
    vehicle_speed_kmh: np.ndarray | None = None

    def __post_init__(self) -> None:
        t = np.asarray(self.time_s)
        for name in (
            "time_s",
            "speed_rpm",
            "torque_nm",
            "fuel_mg_per_cycle",
            "gear",
            "vehicle_speed_kmh",
        ):
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.array(value, dtype=np.int64 if name == "gear" else np.float64)
            if arr.shape != t.shape:
                raise SignalError(f"{name} has shape {arr.shape}, time_s has {t.shape}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def to_signals(self) -> Signals:
        """As :class:`Signals`: ``speed_rpm`` [rpm], ``torque_nm`` [N·m], ``fuel_mg_per_cycle``
        [mg/cycle], ``gear`` [-] and, for vehicle cycles, ``vehicle_speed_kmh`` [km/h]."""
        channels = {
            "speed_rpm": self.speed_rpm,
            "torque_nm": self.torque_nm,
            "fuel_mg_per_cycle": self.fuel_mg_per_cycle,
            "gear": self.gear.astype(np.float64),
        }
        units = {
            "speed_rpm": "rpm",
            "torque_nm": "N·m",
            "fuel_mg_per_cycle": "mg/cycle",
            "gear": "-",
            "vehicle_speed_kmh": "km/h",
        }
        if self.vehicle_speed_kmh is not None:
            channels["vehicle_speed_kmh"] = self.vehicle_speed_kmh
        return Signals(self.time_s, channels, units)


@dataclass(frozen=True, slots=True)
class WhtcReferenceSpeeds:
    """GTR 4 §7.4 reference speeds of an engine's full-load curve (rpm)."""

    n_lo: float  # lowest speed with P = 55 % of P_max
    n_pref: float  # ∫_{n_idle}^{n_pref} T_max dn = 51 % of ∫_{n_idle}^{n_95h} T_max dn
    n_hi: float  # highest speed with P = 70 % of P_max
    n_95h: float  # highest speed with P = 95 % of P_max

    @property
    def reference_speed_rpm(self) -> float:
        """``n_ref = 0.45·n_lo + 0.45·n_pref + 0.1·n_hi`` (rpm)."""
        return 0.45 * self.n_lo + 0.45 * self.n_pref + 0.1 * self.n_hi


# ----------------------------------------------------------------------------- public API


def operating_points(
    cycle: Cycle,
    *,
    rate_hz: float = 10.0,
    vehicle: Vehicle | None = None,
    engine: DieselEngine | None = None,
) -> OperatingPoints:
    """Engine operating points of ``cycle`` at ``rate_hz``: :func:`drive_trace` for vehicle
    cycles, :func:`denormalise_engine_cycle` for engine cycles."""
    if cycle.kind == "engine":
        return denormalise_engine_cycle(cycle, rate_hz=rate_hz, engine=engine)
    assert cycle.speed_kmh is not None
    return drive_trace(
        cycle.time_s,
        cycle.speed_kmh,
        grade_pct=cycle.grade_pct,
        rate_hz=rate_hz,
        vehicle=vehicle,
        engine=engine,
    )


def drive_trace(
    time_s: np.ndarray,
    speed_kmh: np.ndarray,
    *,
    grade_pct: np.ndarray | None = None,
    rate_hz: float = 10.0,
    vehicle: Vehicle | None = None,
    engine: DieselEngine | None = None,
) -> OperatingPoints:
    """Follow a vehicle speed trace (km/h, strictly increasing ``time_s`` in s) with the
    vehicle/gearbox/driver model of the module docstring; output at ``rate_hz`` (Hz) on
    ``t0 + k/rate_hz``. ``grade_pct`` (%) is optional road grade on the same time base."""
    vehicle = Vehicle() if vehicle is None else vehicle
    engine = DieselEngine() if engine is None else engine
    t, v_kmh = _check_trace(time_s, speed_kmh)
    grade = np.zeros_like(t) if grade_pct is None else _check_trace(t, grade_pct, "grade_pct")[1]
    if np.any(v_kmh < 0):
        raise SignalError(f"speed_kmh must be >= 0, got {v_kmh.min():g}")
    t_out = _time_grid(t, rate_hz)
    v_ms, a_ms2 = _pchip(t, v_kmh / 3.6, t_out)
    v_ms = np.maximum(v_ms, 0.0)  # PCHIP cannot undershoot; guard rounding only
    theta = np.arctan(np.interp(t_out, t, grade) / 100.0)
    shift = vehicle.shift
    v_stop_ms = shift.stop_speed_kmh / 3.6
    m = vehicle.mass_kg
    rolling_n = m * _G_MS2 * vehicle.rolling_resistance * np.cos(theta)
    rolling_n *= np.minimum(v_ms / v_stop_ms, 1.0)  # fades out towards standstill
    aero_n = 0.5 * vehicle.air_density_kg_m3 * vehicle.drag_area_m2 * v_ms * v_ms
    force_n = vehicle.rotating_mass_factor * m * a_ms2 + rolling_n + m * _G_MS2 * np.sin(theta)
    force_n += aero_n
    wheel_torque_nm = force_n * vehicle.wheel_radius_m
    ratios = vehicle.overall_ratios()
    eta = vehicle.driveline_efficiency
    if shift.upshift_full_rpm > engine.rated_speed_rpm:
        raise ConfigError(
            f"upshift_full_rpm ({shift.upshift_full_rpm:g}) must not exceed rated speed "
            f"({engine.rated_speed_rpm:g})"
        )
    gear = np.empty(t_out.size, dtype=np.int64)
    speed_rpm = np.empty(t_out.size)
    gearbox_kernel(
        v_ms,
        a_ms2,
        wheel_torque_nm,
        1.0 / rate_hz,
        ratios / vehicle.wheel_radius_m * _RPM_PER_RAD_S,
        ratios,
        eta,
        np.asarray(engine.full_load_speed_rpm, dtype=np.float64),
        np.asarray(engine.full_load_torque_nm, dtype=np.float64),
        engine.idle_speed_rpm,
        engine.rated_speed_rpm,
        shift.upshift_light_rpm,
        shift.upshift_full_rpm,
        shift.downshift_rpm,
        shift.hysteresis_rpm,
        shift.upshift_torque_reserve,
        shift.min_gear_time_s,
        v_stop_ms,
        shift.engage_accel_ms2,
        shift.speed_slew_rpm_per_s,
        gear,
        speed_rpm,
    )
    i = np.where(gear > 0, ratios[np.maximum(gear - 1, 0)], 1.0)
    demand_nm = np.where(
        wheel_torque_nm >= 0, wheel_torque_nm / (i * eta), wheel_torque_nm * eta / i
    )
    in_gear = gear > 0
    driving = in_gear & (demand_nm > 0)
    fuel_cut = in_gear & ~driving & (speed_rpm >= engine.fuel_cut_min_rpm)
    torque_nm = np.where(driving, np.minimum(demand_nm, engine.full_load_torque(speed_rpm)), 0.0)
    torque_nm = np.where(fuel_cut, -engine.friction_torque(speed_rpm), torque_nm)
    fuel = np.where(fuel_cut, 0.0, engine.fuel_mg_per_cycle(torque_nm, speed_rpm))
    return OperatingPoints(t_out, speed_rpm, torque_nm, fuel, gear, v_ms * 3.6)


def whtc_reference_speeds(engine: DieselEngine | None = None) -> WhtcReferenceSpeeds:
    """``n_lo, n_pref, n_hi, n_95h`` of the engine's full-load curve (GTR 4 §7.4.1).

    ``P(n) = T_max(n)·n·π/30`` evaluated on a 0.5 rpm grid from idle to the last full-load
    speed; the integral for ``n_pref`` is trapezoidal. Accuracy ≈ 0.5 rpm.
    """
    engine = DieselEngine() if engine is None else engine
    n = np.arange(engine.idle_speed_rpm, engine.full_load_speed_rpm[-1] + 0.25, 0.5)
    torque = engine.full_load_torque(n)
    power = torque * n / _RPM_PER_RAD_S
    p_max = power.max()
    n_lo = float(n[np.argmax(power >= 0.55 * p_max)])
    n_hi = float(n[power.size - 1 - np.argmax(power[::-1] >= 0.70 * p_max)])
    n_95h = float(n[power.size - 1 - np.argmax(power[::-1] >= 0.95 * p_max)])
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (torque[1:] + torque[:-1]) * np.diff(n))))
    total = np.interp(n_95h, n, cum)
    n_pref = float(np.interp(0.51 * total, cum, n))
    return WhtcReferenceSpeeds(n_lo=n_lo, n_pref=n_pref, n_hi=n_hi, n_95h=n_95h)


def denormalise_engine_cycle(
    cycle: Cycle, *, rate_hz: float = 10.0, engine: DieselEngine | None = None
) -> OperatingPoints:
    """Denormalise an engine cycle (WHTC) for ``engine`` (GTR 4 §7.4), output at ``rate_hz``.

    Normalised speed and torque (%) are first interpolated to ``rate_hz`` (PCHIP), then::

        n = n_norm/100·(0.45·n_lo + 0.45·n_pref + 0.1·n_hi − n_idle)·2.0327 + n_idle
        T = T_norm/100·T_max(n)   (T_norm ≥ 0),     T = T_norm/100·T_fr(n)   (T_norm < 0)

    with the reference speeds of :func:`whtc_reference_speeds`. Negative ``T_norm`` is motoring
    (``−100`` = full drag, the files' ``m``): fuel 0. Otherwise fuel from the Willans line.
    ``gear`` is 0 (no gearbox), ``vehicle_speed_kmh`` is ``None``.
    """
    engine = DieselEngine() if engine is None else engine
    if cycle.kind != "engine" or cycle.speed_pct is None or cycle.torque_pct is None:
        raise ConfigError(f"cycle {cycle.name!r} is a {cycle.kind} cycle, not an engine cycle")
    ref = whtc_reference_speeds(engine)
    n_idle = engine.idle_speed_rpm
    t_out = _time_grid(cycle.time_s, rate_hz)
    speed_pct = _pchip(cycle.time_s, cycle.speed_pct, t_out)[0]
    torque_pct = _pchip(cycle.time_s, cycle.torque_pct, t_out)[0]
    speed_rpm = speed_pct / 100.0 * (ref.reference_speed_rpm - n_idle) * 2.0327 + n_idle
    torque_nm = np.where(
        torque_pct >= 0,
        torque_pct / 100.0 * engine.full_load_torque(speed_rpm),
        torque_pct / 100.0 * engine.friction_torque(speed_rpm),
    )
    fuel = np.where(torque_pct >= 0, engine.fuel_mg_per_cycle(torque_nm, speed_rpm), 0.0)
    return OperatingPoints(t_out, speed_rpm, torque_nm, fuel, np.zeros(t_out.size, np.int64))


# ------------------------------------------------------------------------------- helpers


def _check_trace(
    time_s: np.ndarray, values: np.ndarray, name: str = "speed_kmh"
) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(time_s, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or t.size < 2 or y.shape != t.shape:
        raise SignalError(
            f"{name} and time_s must be 1-D of equal length >= 2, got {y.shape} and {t.shape}"
        )
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise SignalError(f"{name} and time_s must be finite")
    if np.any(np.diff(t) <= 0):
        raise SignalError("time_s must be strictly increasing")
    return t, y


def _time_grid(t: np.ndarray, rate_hz: float) -> np.ndarray:
    if not (np.isfinite(rate_hz) and rate_hz >= 1.0):
        raise ConfigError(f"rate_hz must be a finite number >= 1 Hz, got {rate_hz!r}")
    n = int(np.floor((t[-1] - t[0]) * rate_hz + 1e-9)) + 1
    return t[0] + np.arange(n) / rate_hz


def _pchip(x: np.ndarray, y: np.ndarray, xq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Monotone cubic Hermite interpolation (Fritsch & Carlson 1980) and its derivative.

    Interior slopes: weighted harmonic mean of the neighbouring secants, 0 at local extrema;
    end slopes: the end secants. Each interval stays within its end values (no overshoot).
    """
    h = np.diff(x)
    delta = np.diff(y) / h
    d = np.empty_like(y)
    d[0], d[-1] = delta[0], delta[-1]
    w1 = 2.0 * h[1:] + h[:-1]
    w2 = h[1:] + 2.0 * h[:-1]
    same_sign = delta[:-1] * delta[1:] > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        harmonic = (w1 + w2) / (w1 / delta[:-1] + w2 / delta[1:])
    d[1:-1] = np.where(same_sign, harmonic, 0.0)
    k = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, x.size - 2)
    hk = h[k]
    s = (xq - x[k]) / hk
    s2, s3 = s * s, s * s * s
    yq = (
        (2 * s3 - 3 * s2 + 1) * y[k]
        + (s3 - 2 * s2 + s) * hk * d[k]
        + (-2 * s3 + 3 * s2) * y[k + 1]
        + (s3 - s2) * hk * d[k + 1]
    )
    dyq = (
        (6 * s2 - 6 * s) * (y[k] - y[k + 1]) / hk
        + (3 * s2 - 4 * s + 1) * d[k]
        + (3 * s2 - 2 * s) * d[k + 1]
    )
    return yq, dyq
