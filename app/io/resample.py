"""Channels recorded on their own time bases → one table on one raster.

A measurement file holds each channel on its own timestamps (an MDF channel group per rate,
a sparse CSV export with each channel only on its own rows), with masked samples: non-finite
values, samples flagged invalid, empty cells. :func:`resample` puts the kept channels on
one time base (the rules of `docs/data-formats.md#multi-rate`):

- **Raster.** A rate (``100Hz``, ``1kHz``, ``10ms``, ``0.1s``: a uniform grid from the
  start of the common span) or ``channel:NAME`` (that channel's recorded timestamps).
  Default: the raster of the *slowest* kept channel (largest median time step; the first
  such channel on a tie).
  The grid covers only the span every kept channel covers with valid samples:
  ``[max first valid time, min last valid time]``.
- **Hold or interpolate.** A *held* channel (enumeration, value table, status, boolean)
  takes its previous valid value: ``y(t) = v_k`` with ``t_k = max{t_j ≤ t}`` (zero-order
  hold), so it only ever takes recorded values. Any other channel is interpolated linearly
  between its valid neighbours (``numpy.interp``).
- **Masked samples** (NaN in :attr:`Track.values`: non-finite or flagged invalid) are
  skipped: the value at their time comes from the valid neighbours. A channel with fewer
  than two valid samples has no span: it is dropped with a note. When no channel is
  usable the file is refused.

When every kept channel already has the same timestamps, no sample is masked and no rate
is asked for, the channels are returned unchanged and no note is written.

:func:`shared_time_base` tells whether the tracks are on one time base: an upload whose
aren't, with no raster asked for, is stored as recorded and resampled when it is read, onto
the slowest raster among the channels that read needs: whole (:mod:`app.store.datasets`) or,
for a run, a window at a time by the same rules (:mod:`app.store.raster_rows`, which plans
its raster with :func:`plan_span` from the spans ingest keeps, :func:`span_of`).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.io.errors import InputError

RASTER_FIELD = "raster"
# Few enough distinct integer values to be a state rather than a measurement: the rule for
# columns without metadata (CSV, MCAP), docs/data-formats.md#multi-rate.
MAX_HELD_LEVELS = 16
_RATE = re.compile(
    r"^\s*(?P<number>(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?)\s*(?P<unit>hz|khz|s|ms|us|µs)\s*$",
    re.IGNORECASE | re.ASCII,
)
_STEP_S = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}
_RATE_HZ = {"hz": 1.0, "khz": 1e3}
_CHANNEL_PREFIX = "channel:"


@dataclass(frozen=True, slots=True)
class Track:
    """One channel as recorded: its own timestamps (s, strictly increasing) and float64
    values, NaN where the sample is masked; ``hold`` selects zero-order hold."""

    name: str
    unit: str
    time: np.ndarray
    values: np.ndarray
    hold: bool

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.values)

    @property
    def masked(self) -> int:
        return int(self.values.size - np.count_nonzero(self.valid))


@dataclass(frozen=True, slots=True)
class Raster:
    """A uniform step in seconds, or the name of the channel whose timestamps are used;
    neither: the default (the slowest kept channel)."""

    step: float | None = None
    channel: str | None = None

    def describe(self) -> str:
        if self.step is not None:
            return f"{_format_step(self.step)} raster"
        return f"raster of channel {self.channel!r}"


@dataclass(frozen=True, slots=True)
class Resampled:
    """The common time base, the kept channels on it, what was done (for the notes), and
    the raster used (``None``: the channels' own shared time base, unchanged)."""

    time: np.ndarray
    channels: dict[str, np.ndarray]
    units: dict[str, str]
    masked: dict[str, int]
    notes: list[str]
    raster: Raster | None = None


def parse_raster(text: str | None) -> Raster:
    """``"100Hz"``, ``"1kHz"``, ``"10ms"``, ``"0.5s"``, ``"250us"`` or ``"channel:NAME"``;
    ``None``/blank is the default raster. 422 (field ``raster``) for anything else."""
    if text is None or not text.strip():
        return Raster()
    if text.strip().lower().startswith(_CHANNEL_PREFIX):
        name = text.strip()[len(_CHANNEL_PREFIX) :].strip()
        if not name:
            raise InputError("raster 'channel:' names no channel", field=RASTER_FIELD)
        return Raster(channel=name)
    match = _RATE.match(text)
    if match is None:
        raise InputError(
            f"raster {text.strip()!r} is not understood; give a rate such as '100Hz', "
            "'1kHz', a step such as '10ms', '0.1s', or 'channel:NAME'",
            field=RASTER_FIELD,
        )
    number, unit = float(match["number"]), match["unit"].lower()
    if number == 0 or not np.isfinite(number):
        raise InputError(f"raster {text.strip()!r} must be a positive rate", field=RASTER_FIELD)
    step = number * _STEP_S[unit] if unit in _STEP_S else 1.0 / (number * _RATE_HZ[unit])
    if not (np.isfinite(step) and step > 0):
        raise InputError(f"raster {text.strip()!r} must be a positive rate", field=RASTER_FIELD)
    return Raster(step=step)


def held_by_values(values: np.ndarray) -> bool:
    """The rule for a column without metadata: held when its valid values are all integers
    with at most :data:`MAX_HELD_LEVELS` distinct values, otherwise continuous."""
    valid = values[np.isfinite(values)]
    if valid.size == 0 or not np.all(valid == np.round(valid)):
        return False
    return np.unique(valid).size <= MAX_HELD_LEVELS


def select(tracks: Sequence[Track], names: Sequence[str] | None) -> list[Track]:
    """The tracks named in ``names`` (in that order), or all; 422 (field ``channels``)
    naming a channel the file does not have."""
    if names is None:
        return list(tracks)
    by_name = {t.name: t for t in tracks}
    missing = [n for n in names if n not in by_name]
    if missing:
        shown = [t.name for t in tracks][:50]
        more = f" (and {len(tracks) - 50} more)" if len(tracks) > 50 else ""
        raise InputError(
            f"channel{'s' if len(missing) > 1 else ''} {', '.join(repr(n) for n in missing)} "
            f"not in the file; it has {shown}{more}",
            field="channels",
        )
    return [by_name[n] for n in dict.fromkeys(names)]


def resample(
    tracks: Sequence[Track], raster: Raster, *, max_rows: int, max_values: int
) -> Resampled:
    """The usable ``tracks`` on one time base (module docstring). Refuses, before
    allocating, a rate raster of more than ``max_rows`` rows or ``max_values`` values."""
    notes: list[str] = []
    usable = _usable(tracks, notes)
    masked = {t.name: t.masked for t in usable if t.masked}
    if _unchanged(usable, raster):
        return Resampled(
            usable[0].time,
            {t.name: t.values for t in usable},
            {t.name: t.unit for t in usable},
            masked,
            notes,
        )
    by_name = {t.name: t for t in usable}
    valid_times = {t.name: t.time[t.valid] for t in usable}
    start, stop, raster = plan_span([span_of(t) for t in usable], raster)
    if raster.step is not None:
        time = rate_grid(start, stop, raster.step, len(usable), max_rows, max_values)
    else:
        own = by_name[raster.channel].time  # type: ignore[index]
        time = own[(own >= start) & (own <= stop)]
        _check_size(time.size, len(usable), raster, max_rows, max_values)
    channels = {t.name: on_grid(t, valid_times[t.name], time) for t in usable}
    held = [t.name for t in usable if t.hold]
    smooth = [t.name for t in usable if not t.hold]
    notes.append(
        f"{len(usable)} channel{'s' if len(usable) > 1 else ''} resampled onto the "
        f"{raster.describe()} ({time.size} rows, {start:g}–{stop:g} s): "
        + "; ".join(
            part
            for part in (
                f"held (previous value) {held}" if held else "",
                f"interpolated linearly {smooth}" if smooth else "",
            )
            if part
        )
    )
    return Resampled(time, channels, {t.name: t.unit for t in usable}, masked, notes, raster)


@dataclass(frozen=True, slots=True)
class Span:
    """What the raster rules need of a usable channel: its first and last valid time and
    its median time step (s)."""

    name: str
    start: float
    stop: float
    step: float


def span_of(track: Track) -> Span:
    """The span of a track with at least two valid samples."""
    valid = track.time[track.valid]
    return Span(track.name, float(valid[0]), float(valid[-1]), _median_step(track.time))


def plan_span(spans: Sequence[Span], raster: Raster) -> tuple[float, float, Raster]:
    """The span every channel covers with valid samples, ``[max start, min stop]``, and the
    raster to put them on: ``raster``, or by default that of the slowest channel (largest
    median step, the first on a tie). 422 for a raster channel not among ``spans`` or for
    spans that do not overlap."""
    names = [s.name for s in spans]
    if raster.channel is not None and raster.channel not in names:
        raise InputError(
            f"raster channel {raster.channel!r} is not among the kept channels with usable "
            f"samples: {names[:50]}",
            field=RASTER_FIELD,
        )
    start = max(s.start for s in spans)
    stop = min(s.stop for s in spans)
    if start >= stop:
        raise InputError(
            "the channels' time ranges do not overlap (valid samples of every kept channel "
            f"span {start:g}–{stop:g} s)",
            field="file",
        )
    if raster.step is None and raster.channel is None:
        raster = Raster(channel=max(spans, key=lambda s: s.step).name)
    return start, stop, raster


def rate_grid(
    start: float, stop: float, step: float, channels: int, max_rows: int, max_values: int
) -> np.ndarray:
    """``start + step·k`` for ``k = 0 … ⌊(stop − start)/step · (1 + 10⁻¹²)⌋`` (the last time
    may pass ``stop`` by a rounding: it is held at the channels' last values), refused
    before it is allocated when it exceeds ``max_rows`` rows or ``max_values`` values over
    ``channels``."""
    # a float count: the count of a tiny step overflows an int (and is refused)
    rows = float(np.floor((stop - start) / step * (1 + 1e-12))) + 1
    _check_size(rows, channels, Raster(step=step), max_rows, max_values)
    return start + step * np.arange(int(rows), dtype=np.float64)


def _usable(tracks: Sequence[Track], notes: list[str]) -> list[Track]:
    """Tracks with at least two valid samples; the others are dropped with a note. The
    masked samples of each kept track are counted in a note."""
    usable = []
    for t in tracks:
        valid = int(np.count_nonzero(t.valid))
        if valid < 2:
            notes.append(
                f"channel {t.name!r} dropped: {valid} usable sample{'s' if valid != 1 else ''} "
                f"of {t.values.size}, at least 2 needed"
            )
            continue
        if t.masked:
            notes.append(
                f"channel {t.name!r}: {t.masked} of {t.values.size} samples masked "
                "(non-finite or marked invalid): filled from the valid neighbours"
            )
        usable.append(t)
    if not usable:
        raise InputError(
            "no channel has usable samples (at least 2 finite, valid samples each)",
            field="file",
        )
    return usable


def _unchanged(tracks: Sequence[Track], raster: Raster) -> bool:
    """Nothing to do: one shared time base, no masked sample, no rate or channel asked for
    (a channel raster over a shared time base is that same time base)."""
    first = tracks[0].time
    same = all(t.time is first or np.array_equal(t.time, first) for t in tracks)
    clean = all(t.masked == 0 for t in tracks)
    named = raster.channel is None or raster.channel in {t.name for t in tracks}
    return same and clean and raster.step is None and named


def shared_time_base(tracks: Sequence[Track]) -> bool:
    """Every track has the same timestamps (true of none or one)."""
    first = tracks[0].time if tracks else None
    return all(t.time is first or np.array_equal(t.time, first) for t in tracks)


def _median_step(time: np.ndarray) -> float:
    return float(np.median(np.diff(time)))


def on_grid(track: Track, valid_time: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """``track`` at the grid times from its valid samples: previous value or linear."""
    values = track.values[track.valid]
    if track.hold:
        index = np.searchsorted(valid_time, grid, side="right") - 1
        return values[np.clip(index, 0, None)]  # grid ≥ the first valid time: index ≥ 0
    return np.interp(grid, valid_time, values)


def _check_size(rows: float, channels: int, raster: Raster, max_rows: int, max_values: int) -> None:
    if not (rows <= max_rows and rows * channels <= max_values):  # also refuses inf
        shown = f"{int(rows)}" if np.isfinite(rows) and rows < 1e15 else f"{rows:.3g}"
        raise InputError(
            f"the {raster.describe()} gives {shown} rows × {channels} channels; the limits "
            f"are {max_rows} rows and {max_values} values: choose a slower raster or fewer "
            "channels",
            field=RASTER_FIELD,
        )


def _format_step(step: float) -> str:
    if step >= 1.0:
        return f"{step:g} s"
    if step >= 1e-3:
        return f"{step * 1e3:g} ms"
    return f"{step * 1e6:g} µs"
