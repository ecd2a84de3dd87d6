"""Model mismatch between a scenario's plant and the estimators run on it (docs/fidelity.md).

A scenario is built at a mismatch level (:data:`LEVELS`):

- ``"none"`` — the estimators' model constants are the plant's; the true maps are tables on
  the estimators' grids (exactly representable). This is the perfect-model setting of the
  papers' simulations and of mapwise before issue 17.
- ``"nominal"`` — the true maps are smooth functions evaluated off-grid
  (:mod:`estimation.truth_maps`), and every estimator-side model constant is drawn around the
  plant's value, uniformly within the half-width of its class in :data:`RANGES`.
- ``"severe"`` — as ``"nominal"`` with every half-width doubled.

The draw is seeded from the scenario seed (:func:`draw_seed`, a stream separate from the
sensor noise), so a realisation is reproducible and the estimator config of seed ``s`` does
not depend on any other seed. :class:`MismatchDraw` records every drawn value next to the
plant's, which is what ``ScenarioData.metadata["parameters"]`` and the reports print.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

import numpy as np

from estimation.errors import ConfigError

__all__ = [
    "LEVELS",
    "RANGES",
    "MismatchDraw",
    "MismatchLevel",
    "ParameterClass",
    "check_level",
    "draw_seed",
]

MismatchLevel = Literal["none", "nominal", "severe"]
LEVELS: tuple[str, ...] = get_args(MismatchLevel)
_SCALE = {"none": 0.0, "nominal": 1.0, "severe": 2.0}

ParameterClass = Literal[
    "volume", "efficiency", "flow_area", "inertia", "sensor_time_constant", "noise_sigma", "delay"
]

RANGES: dict[str, float] = {
    "volume": 0.10,
    "efficiency": 0.05,
    "flow_area": 0.05,
    "inertia": 0.10,
    "sensor_time_constant": 0.20,
    "noise_sigma": 0.20,
    "delay": 1.0,
}
"""Half-width of each class under ``"nominal"``: relative (``0.10`` = ±10 %) for every class
but ``delay``, which is in whole samples (±1). ``"severe"`` doubles them."""


def check_level(level: str) -> MismatchLevel:
    """``level`` if it is one of :data:`LEVELS`, else a :class:`ConfigError` naming them."""
    if level not in LEVELS:
        raise ConfigError(f"mismatch must be one of {', '.join(LEVELS)}; got {level!r}")
    return level  # type: ignore[return-value]


def draw_seed(scenario: str, seed: int) -> list[int]:
    """Entropy of the mismatch draw: the scenario seed, a hash of the scenario name and a tag,
    so it never coincides with the noise stream ``default_rng(seed)``."""
    return [int(seed), zlib.crc32(scenario.encode()), 0x4D49534D]  # "MISM"


@dataclass
class MismatchDraw:
    """Draws the estimator-side constants of one realisation and records them.

    Every call consumes the same random numbers at every level (one uniform per constant,
    in call order), so ``"nominal"`` and ``"severe"`` of a seed differ only by the factor 2.
    """

    scenario: str
    seed: int
    level: MismatchLevel
    records: list[dict[str, Any]] = field(default_factory=list)
    _rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        check_level(self.level)
        self._rng = np.random.default_rng(draw_seed(self.scenario, self.seed))

    def half_width(self, cls: ParameterClass) -> float:
        return RANGES[cls] * _SCALE[self.level]

    def relative(self, name: str, plant: float, cls: ParameterClass, unit: str = "") -> float:
        """``plant·(1 + r·u)``, ``u ~ U(−1, 1)``, ``r`` the class's half-width."""
        r = self.half_width(cls)
        u = float(self._rng.uniform(-1.0, 1.0))
        value = float(plant) * (1.0 + r * u)
        self._record(name, plant, value, unit, f"±{100 * r:g} %")
        return value

    def time_constant_pole(self, name: str, pole: float, period_s: float) -> float:
        """A first-order lag pole ``a = exp(−Ts/τ)`` with its time constant ``τ`` drawn
        (class ``sensor_time_constant``)."""
        tau = -period_s / math.log(pole)
        r = self.half_width("sensor_time_constant")
        u = float(self._rng.uniform(-1.0, 1.0))
        drawn = pole if r == 0.0 else math.exp(-period_s / (tau * (1.0 + r * u)))
        self._record(name, pole, drawn, "-", f"τ ±{100 * r:g} %")
        return drawn

    def samples(self, name: str, plant: int) -> int:
        """``plant + d`` samples, ``d`` uniform on the integers within the delay half-width."""
        k = round(self.half_width("delay"))
        u = float(self._rng.uniform(0.0, 1.0))
        d = min(int(u * (2 * k + 1)), 2 * k) - k
        value = max(0, int(plant) + d)
        self._record(name, plant, value, "samples", f"±{k} samples")
        return value

    def _record(self, name: str, plant: float, value: float, unit: str, rng: str) -> None:
        self.records.append(
            {"name": name, "plant": plant, "estimator": value, "unit": unit, "range": rng}
        )

    def values(self) -> dict[str, float]:
        """Name → estimator-side value of everything drawn so far; empty at ``"none"``, where
        the estimators' documented defaults are the plant's values."""
        if self.level == "none":
            return {}
        return {r["name"]: r["estimator"] for r in self.records}
