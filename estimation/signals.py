"""``Signals``: a time base plus named float channels with units.

What every simulator produces and every importer returns. Validation lives here: strictly
increasing finite time, equal lengths, finite values, required channels present.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from estimation.errors import ConfigError, SignalError


class Signals:
    """Time series sampled on a common time base.

    Parameters
    ----------
    time : (n,) strictly increasing sample times in seconds.
    channels : mapping ``name → (n,)`` float array.
    units : mapping ``name → unit`` (missing names get ``""``).
    copy : copy the arrays (the default), or, with ``False``, take float64 arrays as they
        are and make them read-only: for a reader that hands over columns it built and will
        not write again (a 45 MB log's columns are then not copied once more).
    """

    __slots__ = ("channels", "time", "units")

    def __init__(
        self,
        time: Sequence[float] | np.ndarray,
        channels: Mapping[str, Sequence[float] | np.ndarray],
        units: Mapping[str, str] | None = None,
        *,
        copy: bool = True,
    ) -> None:
        as_array = np.array if copy else np.asarray
        t = as_array(time, dtype=np.float64)
        if t.ndim != 1:
            raise SignalError(f"time must be 1-D, got shape {t.shape}")
        _require_finite("time", t)
        if t.size > 1:
            steps = np.diff(t)
            if np.any(steps <= 0):
                k = int(np.argmax(steps <= 0)) + 1
                kind = "duplicate" if steps[k - 1] == 0 else "decreasing"
                raise SignalError(
                    f"time must be strictly increasing: {kind} time {t[k]:g} s at sample {k} "
                    f"(previous {t[k - 1]:g} s)"
                )
        data: dict[str, np.ndarray] = {}
        for name, values in channels.items():
            arr = as_array(values, dtype=np.float64)
            if arr.shape != t.shape:
                raise SignalError(f"channel {name!r} has {arr.size} samples, time has {t.size}")
            _require_finite(name, arr)
            arr.setflags(write=False)
            data[name] = arr
        t.setflags(write=False)
        units = dict(units or {})
        self.time = t
        self.channels = data
        self.units = {name: str(units.get(name, "")) for name in data}

    def __len__(self) -> int:
        return int(self.time.size)

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.channels[name]
        except KeyError:
            raise SignalError(
                f"missing channel {name!r}; available: {sorted(self.channels)}"
            ) from None

    def __contains__(self, name: object) -> bool:
        return name in self.channels

    @property
    def names(self) -> list[str]:
        return list(self.channels)

    def require(self, names: Iterable[str]) -> None:
        """Raise :class:`SignalError` naming every required channel that is missing."""
        missing = [n for n in names if n not in self.channels]
        if missing:
            raise SignalError(
                f"missing channel{'s' if len(missing) > 1 else ''} "
                f"{', '.join(repr(n) for n in missing)}; available: {sorted(self.channels)}"
            )

    def stack(self, names: Sequence[str]) -> np.ndarray:
        """The channels ``names`` as columns of an ``(n, len(names))`` array."""
        self.require(names)
        return (
            np.column_stack([self.channels[n] for n in names])
            if names
            else np.empty((len(self), 0))
        )

    def sample_period(self, *, tolerance: float = 0.01) -> float:
        """The constant sample period ``Ts`` in seconds (:func:`uniform_period`)."""
        return uniform_period(self.time, tolerance=tolerance)

    def slice(self, start: int, stop: int) -> Signals:
        return Signals(
            self.time[start:stop],
            {n: v[start:stop] for n, v in self.channels.items()},
            self.units,
        )

    def __repr__(self) -> str:
        span = f"{self.time[0]:g}–{self.time[-1]:g} s" if len(self) else "empty"
        return f"Signals({len(self)} samples, {span}, channels={self.names})"


def _require_finite(name: str, arr: np.ndarray) -> None:
    if not np.all(np.isfinite(arr)):
        k = int(np.argmax(~np.isfinite(arr)))
        raise SignalError(f"channel {name!r} has a non-finite value ({arr[k]}) at sample {k}")


def delay_samples(delay_s: float, sample_period_s: float) -> int:
    """A transport delay in whole samples: ``floor(τ/Ts + 1/2)`` (ties round up).

    A tolerance of 1e-6 samples absorbs floating-point noise in ``Ts``, so the NOx case's
    0.75 s at 50 Hz is 38 samples however the time base was built (SKF (34) gives τ in
    seconds although its model (2) needs whole samples).

    >>> delay_samples(0.75, 0.02)
    38
    """
    if sample_period_s <= 0.0:
        raise ConfigError(f"sample period must be > 0 s, got {sample_period_s!r}")
    if delay_s < 0.0:
        raise ConfigError(f"delay must be >= 0 s, got {delay_s!r}")
    return math.floor(delay_s / sample_period_s + 0.5 + 1e-6)


def uniform_period(time: np.ndarray, *, tolerance: float = 0.01) -> float:
    """The constant sample period ``Ts = median(Δt)`` [s] of a time column.

    Raises :class:`SignalError` when a step differs from it by more than ``tolerance``
    (relative) — estimators that count delays in samples need a fixed rate. One array of
    steps is its only allocation the size of the log (the median partitions it in place), so
    a streamed run can check its whole time column (8 bytes a sample) for 8 bytes more.
    """
    if time.size < 2:
        raise SignalError("a sample period needs at least two samples")
    steps = np.diff(time)
    ts = float(np.median(steps, overwrite_input=True))
    worst = max(
        float(np.max(np.abs(steps[a : a + _BLOCK] - ts))) for a in range(0, steps.size, _BLOCK)
    )
    if worst > tolerance * ts:
        steps = np.diff(time)  # in log order again, to name the step
        k = int(np.argmax(np.abs(steps - ts))) + 1
        raise SignalError(
            f"time is not uniformly sampled: step {steps[k - 1]:g} s at sample {k} vs median "
            f"{ts:g} s; resample to a fixed rate first"
        )
    return ts


_BLOCK = 1 << 16  # steps compared with the median at a time
