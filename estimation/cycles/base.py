"""The :class:`Cycle` record shared by the file loaders and the synthetic generators."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from estimation.errors import SignalError


@dataclass(frozen=True, slots=True, eq=False)
class Cycle:
    """A test cycle sampled at 1 Hz.

    A *vehicle* cycle carries ``speed_kmh`` (and optionally ``grade_pct``, road grade in
    percent = 100·rise/run); an *engine* cycle carries the normalised ``speed_pct`` and
    ``torque_pct`` of GTR 4 (WHTC). Negative ``torque_pct`` means motoring: ``−100`` is the
    full drag torque of the engine (the cycle files write motoring points as ``m``).

    All arrays are ``(n,)``, read-only, on the common time base ``time_s`` (s, starting at 0).
    """

    name: str
    kind: Literal["vehicle", "engine"]
    time_s: np.ndarray
    source: str
    speed_kmh: np.ndarray | None = None
    grade_pct: np.ndarray | None = None
    speed_pct: np.ndarray | None = None
    torque_pct: np.ndarray | None = None

    def __post_init__(self) -> None:
        t = _frozen_array("time_s", self.time_s, None)
        if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
            raise SignalError(f"cycle {self.name!r}: time_s must be 1-D strictly increasing")
        object.__setattr__(self, "time_s", t)
        if self.kind == "vehicle":
            wanted, unwanted = ("speed_kmh",), ("speed_pct", "torque_pct")
        elif self.kind == "engine":
            wanted, unwanted = ("speed_pct", "torque_pct"), ("speed_kmh", "grade_pct")
        else:
            raise SignalError(f"cycle kind must be 'vehicle' or 'engine', got {self.kind!r}")
        for name in (*wanted, "grade_pct"):
            value = getattr(self, name)
            if value is None:
                if name in wanted:
                    raise SignalError(f"{self.kind} cycle {self.name!r} needs {name}")
                continue
            object.__setattr__(self, name, _frozen_array(name, value, t.shape))
        for name in unwanted:
            if getattr(self, name) is not None:
                raise SignalError(f"{self.kind} cycle {self.name!r} cannot have {name}")
        if self.speed_kmh is not None and np.any(self.speed_kmh < 0):
            k = int(np.argmin(self.speed_kmh))
            raise SignalError(
                f"cycle {self.name!r}: negative speed {self.speed_kmh[k]:g} km/h at {t[k]:g} s"
            )

    @property
    def duration_s(self) -> float:
        """``t_end − t_start`` in seconds."""
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def distance_km(self) -> float:
        """Trapezoidal integral ``∫ v dt`` of a vehicle cycle in km (0 for engine cycles)."""
        if self.speed_kmh is None:
            return 0.0
        return float(np.trapezoid(self.speed_kmh, self.time_s) / 3600.0)


def _frozen_array(name: str, value: object, shape: tuple[int, ...] | None) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if shape is not None and arr.shape != shape:
        raise SignalError(f"{name} has shape {arr.shape}, time_s has {shape}")
    if not np.all(np.isfinite(arr)):
        raise SignalError(
            f"{name} has a non-finite value at sample {int(np.argmax(~np.isfinite(arr)))}"
        )
    arr.setflags(write=False)
    return arr
