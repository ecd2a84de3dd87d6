"""Synthetic vehicle cycles.

``sdmp`` imitates the *Sportive Driving Mountain Profile* of Guardiola et al. (SKF paper §2,
§6.2, Fig. 2): a test with sharp variations of injected fuel and engine speed, used there to
learn a NOx map; the NEDC serves as the slow counterpart.
"""

from __future__ import annotations

import math

import numpy as np

from estimation.cycles.base import Cycle
from estimation.errors import ConfigError

_G_MS2 = 9.81
_SPECIFIC_POWER_W_PER_KG = 55.0  # acceleration budget, ~70 % of a 75 kW/t light-duty diesel
_ROLLING_AND_AERO_MS2 = 0.3  # allowance for rolling and aero drag in that budget
_STOP_PROBABILITY = 0.15  # share of corners that are a stop (hairpin, junction)


def make_sdmp(*, seed: int = 0, duration_s: int = 1200) -> Cycle:
    """A Sportive-Driving-Mountain-Profile-like vehicle cycle, deterministic in ``seed``.

    Construction (1 Hz, ``duration_s`` seconds, ``np.random.default_rng(seed)``):

    1. **Road grade** ``grade_pct(t)``: alternating climbs and descents of U(120, 300) s with
       ``|grade|`` ~ U(4, 9) %, starting with a climb, joined by 21 s raised-cosine blends.
    2. **Speed**: 5 s idle, then repeated *straight → corner* units: accelerate to a straight
       speed U(50, 110) km/h, hold U(2, 10) s, brake at U(2.5, 5) m/s² to a corner speed
       U(20, 50) km/h (or, with probability 0.15, to a stop held U(3, 10) s), hold U(1, 4) s.
       Acceleration is U(1.8, 3.2) m/s², capped by a specific-power budget
       ``a ≤ P/m / v − g·(max(grade, 0) + 0.3/g)`` with ``P/m = 55 W/kg`` (v the target speed),
       floored at 0.5 m/s², so a 2 L diesel car can follow it. Ramps are constant-acceleration.
    3. The last unit that fits is followed by braking at 3 m/s² to a stop and idle to the end.

    Returns a ``kind='vehicle'`` :class:`Cycle` named ``'sdmp'`` with ``speed_kmh`` and
    ``grade_pct``, ``time_s = 0, 1, …, duration_s``.
    """
    if int(duration_s) != duration_s or duration_s < 120:
        raise ConfigError(f"sdmp duration_s must be an integer >= 120 s, got {duration_s!r}")
    n = int(duration_s) + 1
    rng = np.random.default_rng(seed)
    grade_pct = _mountain_grade(rng, n)

    parts: list[np.ndarray] = [np.zeros(5)]
    length = 5
    v_kmh = 0.0
    while True:
        v_top = rng.uniform(50.0, 110.0)
        grade_here = max(float(grade_pct[min(length, n - 1)]), 0.0) / 100.0
        budget = _SPECIFIC_POWER_W_PER_KG / (v_top / 3.6) - _G_MS2 * grade_here
        a_up = max(min(rng.uniform(1.8, 3.2), budget - _ROLLING_AND_AERO_MS2), 0.5)
        stop = rng.uniform() < _STOP_PROBABILITY
        v_corner = 0.0 if stop else rng.uniform(20.0, 50.0)
        unit = [
            _ramp(v_kmh, v_top, a_up),
            np.full(int(rng.integers(2, 11)), v_top),
            _ramp(v_top, v_corner, rng.uniform(2.5, 5.0)),
            np.full(int(rng.integers(3, 11) if stop else rng.integers(1, 5)), v_corner),
        ]
        unit_len = sum(p.size for p in unit)
        if length + unit_len + _ramp(v_corner, 0.0, 3.0).size + 1 > n:
            break
        parts.extend(unit)
        length += unit_len
        v_kmh = v_corner
    parts.append(_ramp(v_kmh, 0.0, 3.0))
    speed = np.concatenate(parts)
    speed = np.concatenate((speed, np.zeros(n - speed.size)))
    return Cycle(
        name="sdmp",
        kind="vehicle",
        time_s=np.arange(n, dtype=np.float64),
        speed_kmh=speed,
        grade_pct=grade_pct,
        source=f"synthetic Sportive Driving Mountain Profile (make_sdmp, seed={seed}); after "
        "Guardiola et al., SKF paper Fig. 2",
    )


def _ramp(v0_kmh: float, v1_kmh: float, accel_ms2: float) -> np.ndarray:
    """Samples at t = 1, 2, … of a constant-acceleration ramp from ``v0`` to ``v1`` (km/h)."""
    step = 3.6 * accel_ms2
    k = max(math.ceil(abs(v1_kmh - v0_kmh) / step), 1)
    v = v0_kmh + np.sign(v1_kmh - v0_kmh) * step * np.arange(1, k + 1)
    return np.clip(v, min(v0_kmh, v1_kmh), max(v0_kmh, v1_kmh))


def _mountain_grade(rng: np.random.Generator, n: int) -> np.ndarray:
    lengths, grades = [], []
    sign = 1.0
    while sum(lengths) < n:
        lengths.append(int(rng.integers(120, 301)))
        grades.append(sign * rng.uniform(4.0, 9.0))
        sign = -sign
    steps = np.repeat(grades, lengths)[:n]
    window = np.hanning(23)[1:-1]  # 21 non-zero taps
    padded = np.pad(steps, window.size // 2, mode="edge")
    return np.convolve(padded, window / window.sum(), mode="valid")
