"""Engine-out NOx ground truth: a drifting static map seen through a delayed, lagged sensor.

Source: Guardiola et al., *SKF look-up table NOx* paper (``papers/skf-lookup-table-nox.txt``),
§6.1 (23)–(33) and the case-study settings (34), (36); docs/algorithms.md §2.6 and §6.

Model, per sample ``k`` at the record's fixed sample period ``Ts`` (50 Hz in the paper):

* **Map** — ``T_base(n, m_f)`` in ppm on the 12×18 grid of SKF (34)::

      n   = [750 780 1000 1250 1500 1750 2000:500:4500]  rpm          (12 breakpoints)
      m_f = [0:5:30 34:4:50 55:5:80]                      mg/stroke    (18 breakpoints)

  Node values come from :func:`nox_base_ppm` (smooth, documented there); between nodes the
  map is bilinear interpolation (SKF (10)), clamped outside the grid (docs/algorithms.md §1). The
  truth *is* the table, so a perfect estimator can reach zero map error.
* **Drift / aging** — at engine age ``A`` hours the true map is affine in age::

      T_A(n, m_f) = (1 + γ·A) · T_base(n, m_f) + δ·A                                  [ppm]

  ``γ = drift_gain_per_h`` (default 3 %/h, multiplicative) and ``δ = drift_offset_ppm_per_h``
  (default 5 ppm/h, additive, uniform over the map). ``A_k = start_age_h + (t_k − t_0)/3600``.
* **True NOx** (SKF (24)) — ``x(k) = T_{A_k}(n_k, m_f,k)``. Because interpolation is linear in
  the node values, this equals ``(1 + γ·A_k)·T_base(u_k) + δ·A_k``.
* **Sensor** (SKF (2), (25); docs/algorithms.md §2.6) — delay of ``τ`` samples and first-order lag::

      y_M(k) = a·y_M(k−1) + (1−a)·x(k−τ)

  with ``a = 0.96`` and ``τ = round_half_up(0.75 s / Ts)`` = **38** samples at 50 Hz (0.75 s is
  37.5 samples; SKF (2) requires ``τ ∈ Z+``, so we round half up — ``round`` with ties to even
  gives 38 too). Pre-history: ``x(j) = x(0)`` for ``j < 0`` and, by default,
  ``y_M(−1) = x(0)`` (sensor in steady state at the first operating point).
* **Measurement** — ``y(k) = y_M(k) + v(k)``, ``v ~ N(0, σv²)``, ``σv = 25 ppm`` as SKF (34),
  drawn from ``np.random.default_rng(seed)``. Not clipped at zero (clipping would bias ``v``).

The inputs ``speed_rpm`` and ``fuel_mg_per_stroke`` are returned *undelayed* (as the ECU sees
them); an estimator applies the delay itself (SKF (23)).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from estimation.errors import ConfigError, SignalError
from estimation.kernels.sensor import sensor_kernel
from estimation.signals import Signals, delay_samples
from estimation.table import Axis, Table

SPEED_BREAKPOINTS_RPM: tuple[float, ...] = (
    750.0, 780.0, 1000.0, 1250.0, 1500.0, 1750.0,
    2000.0, 2500.0, 3000.0, 3500.0, 4000.0, 4500.0,
)  # fmt: skip
"""Speed axis of SKF (34): ``[750 780 1000 1250 1500 1750 2000:500:4500]`` rpm (12 points)."""

FUEL_BREAKPOINTS_MG_PER_STROKE: tuple[float, ...] = (
    0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0,
    34.0, 38.0, 42.0, 46.0, 50.0,
    55.0, 60.0, 65.0, 70.0, 75.0, 80.0,
)  # fmt: skip
"""Fuel axis of SKF (34): ``[0:5:30 34:4:50 55:5:80]`` mg/stroke (18 points)."""

SPEED_CHANNEL = "speed_rpm"
FUEL_CHANNEL = "fuel_mg_per_stroke"
NOX_CHANNEL = "nox_ppm"

SECONDS_PER_HOUR = 3600.0

# Constants of the analytic base map (see nox_base_ppm).
_NOX_FLOOR_PPM = 20.0
_NOX_SPAN_PPM = 1850.0
_FUEL_FULL_MG = 80.0
_LOAD_EXPONENT = 1.5
_SPEED_PEAK_RPM = 2250.0
_SPEED_WIDTH_RPM = 1250.0
_SPEED_BASE_FRACTION = 0.5


@dataclass(frozen=True, slots=True)
class NoxFilterSettings:
    """Filter calibration of the paper's NOx case (docs/algorithms.md §2.6).

    ``sigma_v2`` measurement noise variance [ppm²], ``sigma_w2`` random-walk variance of each
    table cell per sample [ppm²], ``sigma_f2`` extra process noise on the sensor state ``y_M``
    [ppm²] (SKF (33)), ``lag`` the sensor pole ``a`` [-], ``delay_s`` the delay ``τ`` [s].
    """

    sigma_v2: float
    sigma_w2: float
    sigma_f2: float
    lag: float
    delay_s: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


NOX_FILTER_CAL_34 = NoxFilterSettings(
    sigma_v2=25.0**2, sigma_w2=15.0**2, sigma_f2=50.0**2, lag=0.96, delay_s=0.75
)
"""SKF (34): ``σv² = 25², σw² = 15², σf² = 50², a = 0.96, τ = 0.75 s`` at 50 Hz."""

NOX_FILTER_CAL_36 = NoxFilterSettings(
    sigma_v2=25.0**2, sigma_w2=7.0**2, sigma_f2=50.0**2, lag=0.96, delay_s=0.75
)
"""SKF (36): the low-gain calibration, ``σw² = 7²`` (other values as (34))."""


@dataclass(frozen=True, slots=True)
class NoxParams:
    """Plant parameters (all keyword, all with units).

    lag : sensor pole ``a`` of ``y_M(k) = a·y_M(k−1) + (1−a)·x(k−τ)``, in ``[0, 1)`` (SKF (34)).
    delay_s : sensor delay ``τ`` in seconds; rounded half up to whole samples (SKF (2), (34)).
    noise_std_ppm : measurement noise standard deviation ``σv`` [ppm] (SKF (34)); 0 = none.
    drift_gain_per_h : multiplicative drift ``γ`` [1/h] of ``T_A = (1+γA)·T_base + δA``.
    drift_offset_ppm_per_h : additive drift ``δ`` [ppm/h], uniform over the map.
    start_age_h : engine age ``A`` [h] at the first sample.
    sensor_initial_ppm : ``y_M(−1)`` [ppm]; ``None`` = steady state at ``x(0)``.
    """

    lag: float = 0.96
    delay_s: float = 0.75
    noise_std_ppm: float = 25.0
    drift_gain_per_h: float = 0.03
    drift_offset_ppm_per_h: float = 5.0
    start_age_h: float = 0.0
    sensor_initial_ppm: float | None = None

    def __post_init__(self) -> None:
        for name in (
            "lag",
            "delay_s",
            "noise_std_ppm",
            "drift_gain_per_h",
            "drift_offset_ppm_per_h",
            "start_age_h",
        ):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value):
                raise ConfigError(f"NoxParams.{name} must be a finite number, got {value!r}")
        if not 0.0 <= self.lag < 1.0:
            raise ConfigError(f"NoxParams.lag must be in [0, 1), got {self.lag!r}")
        if self.delay_s < 0.0:
            raise ConfigError(f"NoxParams.delay_s must be >= 0 s, got {self.delay_s!r}")
        if self.noise_std_ppm < 0.0:
            raise ConfigError(
                f"NoxParams.noise_std_ppm must be >= 0 ppm, got {self.noise_std_ppm!r}"
            )
        if self.start_age_h < 0.0:
            raise ConfigError(f"NoxParams.start_age_h must be >= 0 h, got {self.start_age_h!r}")
        s0 = self.sensor_initial_ppm
        if s0 is not None and (not isinstance(s0, int | float) or not math.isfinite(s0)):
            raise ConfigError(
                f"NoxParams.sensor_initial_ppm must be None or a finite number, got {s0!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


DEFAULT_NOX_PARAMS = NoxParams()


def nox_axes() -> tuple[Axis, Axis]:
    """The two axes of SKF (34): ``speed_rpm`` [rpm] (12) × ``fuel_mg_per_stroke`` (18)."""
    return (
        Axis(SPEED_CHANNEL, "rpm", SPEED_BREAKPOINTS_RPM),
        Axis(FUEL_CHANNEL, "mg/stroke", FUEL_BREAKPOINTS_MG_PER_STROKE),
    )


def nox_base_ppm(speed_rpm: np.ndarray, fuel_mg_per_stroke: np.ndarray) -> np.ndarray:
    """Analytic engine-out NOx at age 0, in ppm (an invented but plausible diesel shape).

    ``T_base(n, m_f) = 20 + 1850 · (m_f/80)^1.5 · (0.5 + 0.5·exp(−((n − 2250)/1250)²))``

    * rises strictly with load (``m_f``): thermal NOx follows combustion temperature;
      low-load NOx is kept low by EGR, hence the convex ``1.5`` power;
    * peaks at mid speed (2250 rpm) and full load (80 mg/stroke); at the grid edges speed
      keeps ≥ 50 % of the peak;
    * range 20 ppm (motoring, ``m_f = 0``) to 1870 ppm (unreachable peak between nodes).

    Inputs broadcast; ``m_f`` is not clipped, so pass values in ``[0, 80]``.
    """
    n = np.asarray(speed_rpm, dtype=np.float64)
    m = np.asarray(fuel_mg_per_stroke, dtype=np.float64)
    load = (m / _FUEL_FULL_MG) ** _LOAD_EXPONENT
    speed = _SPEED_BASE_FRACTION + (1.0 - _SPEED_BASE_FRACTION) * np.exp(
        -(((n - _SPEED_PEAK_RPM) / _SPEED_WIDTH_RPM) ** 2)
    )
    return _NOX_FLOOR_PPM + _NOX_SPAN_PPM * load * speed


def nox_base_map() -> Table:
    """The age-0 true map: :func:`nox_base_ppm` at the 12×18 nodes of SKF (34), in ppm."""
    axes = nox_axes()
    n, m = np.meshgrid(axes[0].breakpoints, axes[1].breakpoints, indexing="ij")
    return Table(axes, nox_base_ppm(n, m))


def drifted_map(base_map: Table, age_h: float, params: NoxParams = DEFAULT_NOX_PARAMS) -> Table:
    """True map at engine age ``A`` hours: ``T_A = (1 + γ·A)·T_base + δ·A`` [ppm]."""
    gain = 1.0 + params.drift_gain_per_h * age_h
    return base_map.with_values(gain * base_map.values + params.drift_offset_ppm_per_h * age_h)


@dataclass(frozen=True, slots=True)
class NoxTruth:
    """What :func:`simulate_nox` knows and the estimator must find (arrays are read-only).

    time_s : (n,) sample times [s] (same as the returned ``Signals``).
    nox_true_ppm : (n,) true engine-out NOx ``x(k) = T_{A_k}(u_k)`` [ppm] (SKF (24)).
    nox_sensor_noise_free_ppm : (n,) sensor output before noise, ``y_M(k)`` [ppm] (SKF (25)).
    noise_ppm : (n,) the measurement noise ``v(k)`` added to ``y_M`` [ppm].
    base_map, initial_map, final_map : true maps at age 0, at the first and at the last sample.
    params : the plant parameters used.
    delay_samples : ``τ`` in samples.
    sample_period_s : ``Ts`` [s].
    seed : the noise seed.
    """

    time_s: np.ndarray
    nox_true_ppm: np.ndarray
    nox_sensor_noise_free_ppm: np.ndarray
    noise_ppm: np.ndarray
    base_map: Table
    initial_map: Table
    final_map: Table
    params: NoxParams
    delay_samples: int
    sample_period_s: float
    seed: int

    def age_h_at(self, time_s: float) -> float:
        """Engine age [h] at record time ``time_s`` [s]: ``A = start_age_h + (t − t_0)/3600``."""
        return self.params.start_age_h + (float(time_s) - float(self.time_s[0])) / SECONDS_PER_HOUR

    def map_at(self, time_s: float) -> Table:
        """The true map ``T_A`` [ppm] at record time ``time_s`` [s] (any time, not only samples)."""
        return drifted_map(self.base_map, self.age_h_at(time_s), self.params)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dictionary (lists and floats only)."""
        return {
            "time_s": self.time_s.tolist(),
            "nox_true_ppm": self.nox_true_ppm.tolist(),
            "nox_sensor_noise_free_ppm": self.nox_sensor_noise_free_ppm.tolist(),
            "noise_ppm": self.noise_ppm.tolist(),
            "base_map": self.base_map.to_dict(),
            "initial_map": self.initial_map.to_dict(),
            "final_map": self.final_map.to_dict(),
            "params": self.params.to_dict(),
            "delay_samples": self.delay_samples,
            "sample_period_s": self.sample_period_s,
            "seed": self.seed,
        }


def simulate_nox(
    time_s: np.ndarray,
    speed_rpm: np.ndarray,
    fuel_mg_per_stroke: np.ndarray,
    *,
    seed: int,
    params: NoxParams = DEFAULT_NOX_PARAMS,
    base_map: Table | None = None,
    base_function: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[Signals, NoxTruth]:
    """Simulate the measured NOx sensor signal for an operating-point trajectory.

    Equations (module docstring): ``x(k) = T_{A_k}(n_k, m_f,k)`` (SKF (24)),
    ``y_M(k) = a·y_M(k−1) + (1−a)·x(k−τ)`` (SKF (25)), ``y(k) = y_M(k) + v(k)``.

    Parameters
    ----------
    time_s : (n,) uniformly sampled, strictly increasing times [s] (n ≥ 2; 50 Hz in SKF).
    speed_rpm : (n,) engine speed [rpm], ≥ 0.
    fuel_mg_per_stroke : (n,) injected fuel [mg/stroke], ≥ 0. Both clamp at the grid edges.
    seed : seed of ``np.random.default_rng`` for the measurement noise.
    params : :class:`NoxParams`.
    base_map : age-0 true map over axes (``speed_rpm``, ``fuel_mg_per_stroke``);
        default :func:`nox_base_map`.
    base_function : if given, the age-0 truth evaluated off-grid at the operating points
        ``(n, 2)`` instead of interpolating ``base_map`` (which then gives the truth at the
        nodes only; :mod:`estimation.truth_maps`, docs/fidelity.md).

    Returns
    -------
    signals : channels ``speed_rpm`` [rpm], ``fuel_mg_per_stroke`` [mg/stroke] (undelayed)
        and ``nox_ppm`` [ppm] (measured sensor output ``y``).
    truth : :class:`NoxTruth`.
    """
    inputs = Signals(
        time_s,
        {SPEED_CHANNEL: speed_rpm, FUEL_CHANNEL: fuel_mg_per_stroke},
        {SPEED_CHANNEL: "rpm", FUEL_CHANNEL: "mg/stroke"},
    )
    if len(inputs) < 2:
        raise SignalError(f"simulate_nox needs at least two samples, got {len(inputs)}")
    inputs.sample_period()  # raises SignalError unless uniformly sampled (delay in samples)
    ts = float((inputs.time[-1] - inputs.time[0]) / (len(inputs) - 1))  # mean spacing, exact
    for name in (SPEED_CHANNEL, FUEL_CHANNEL):
        values = inputs[name]
        if np.any(values < 0.0):
            k = int(np.argmax(values < 0.0))
            raise SignalError(f"channel {name!r} must be >= 0, got {values[k]:g} at sample {k}")
    if not isinstance(seed, int | np.integer) or isinstance(seed, bool):
        raise ConfigError(f"seed must be an int, got {seed!r}")
    if base_map is None:
        base_map = nox_base_map()
    elif [a.name for a in base_map.axes] != [SPEED_CHANNEL, FUEL_CHANNEL]:
        raise ConfigError(
            f"base_map axes must be [{SPEED_CHANNEL!r}, {FUEL_CHANNEL!r}], "
            f"got {[a.name for a in base_map.axes]}"
        )

    t = inputs.time
    age_h = params.start_age_h + (t - t[0]) / SECONDS_PER_HOUR
    initial_map = drifted_map(base_map, float(age_h[0]), params)
    final_map = drifted_map(base_map, float(age_h[-1]), params)
    for label, table in (("initial", initial_map), ("final", final_map)):
        if np.any(table.values < 0.0):
            raise ConfigError(
                f"drift makes the {label} true map negative (min {table.values.min():g} ppm); "
                f"check drift_gain_per_h={params.drift_gain_per_h!r}, "
                f"drift_offset_ppm_per_h={params.drift_offset_ppm_per_h!r}"
            )

    U = inputs.stack([SPEED_CHANNEL, FUEL_CHANNEL])
    base = base_map.evaluate(U) if base_function is None else base_function(U)
    x = (1.0 + params.drift_gain_per_h * age_h) * base + params.drift_offset_ppm_per_h * age_h

    tau = delay_samples(params.delay_s, ts)
    y_init = float(x[0]) if params.sensor_initial_ppm is None else float(params.sensor_initial_ppm)
    y_m = np.empty_like(x)
    sensor_kernel(x, tau, float(params.lag), y_init, y_m)

    rng = np.random.default_rng(seed)
    noise = params.noise_std_ppm * rng.standard_normal(x.size)
    y = y_m + noise

    for arr in (x, y_m, noise):
        arr.setflags(write=False)
    signals = Signals(
        t,
        {SPEED_CHANNEL: inputs[SPEED_CHANNEL], FUEL_CHANNEL: inputs[FUEL_CHANNEL], NOX_CHANNEL: y},
        {SPEED_CHANNEL: "rpm", FUEL_CHANNEL: "mg/stroke", NOX_CHANNEL: "ppm"},
    )
    truth = NoxTruth(
        time_s=t,
        nox_true_ppm=x,
        nox_sensor_noise_free_ppm=y_m,
        noise_ppm=noise,
        base_map=base_map,
        initial_map=initial_map,
        final_map=final_map,
        params=params,
        delay_samples=tau,
        sample_period_s=ts,
        seed=int(seed),
    )
    return signals, truth
