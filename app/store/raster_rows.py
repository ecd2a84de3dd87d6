"""A dataset stored as recorded, read a window at a time on a raster.

:class:`RasterRows` is the streamed counterpart of :func:`app.store.datasets.load_on_raster`
(`docs/data-formats.md#streamed-runs`). It plans the raster by the same rules
(:func:`app.io.resample.plan_span`), from the channels' spans that ingest keeps on the
dataset's row (:attr:`app.domain.Channel.timing`) instead of from the samples. One pass over
the stored row groups then notes each group's first and last time and, per channel, its
first and last valid sample (and, for a channel's raster, that channel's sample times). The
run holds the raster's times (8 bytes a row) and those few values a row group.

Row ``k`` of its raster equals row ``k`` of the whole read, bit for bit. A window is made
:data:`SPAN_GROUPS` stored row groups at a time. Zero-order hold reads only the last valid
sample at or before each time, and ``numpy.interp`` only the two valid samples around it (or
the last one, past a channel's last sample). So each part decodes the groups that hold its
span and adds, for a channel without it there, that one neighbouring valid sample from the
pass's notes: a masked run or a channel logged only when it changes never makes a part
decode the groups across it.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from app.io.arrow_arrays import float64_values, valid_rows
from app.io.errors import InputError
from app.io.resample import Raster, Span, Track, on_grid, plan_span, rate_grid
from app.store.errors import ArtifactCorruptError
from app.store.parquet_signals import SignalsFile
from estimation.signals import Signals

CACHED_GROUPS = 8  # as app.store.log_rows: the row groups a window and its neighbours span
SPAN_GROUPS = 2  # stored row groups resampled at a time (one more when a part straddles)


@dataclass(frozen=True, slots=True)
class _Group:
    """One decoded row group: its times, and per channel its values (NaN where masked or
    absent) and the rows where it has a sample."""

    time: np.ndarray
    values: list[np.ndarray]
    present: list[np.ndarray]


class RasterRows:
    """Rows of a dataset stored as recorded, on a raster (module docstring).

    ``spans``: each channel's first and last valid time and median step, as ingest found
    them; a channel without one, or with fewer than two valid samples, is left out, as
    :func:`app.io.resample.resample` drops it. ``raster`` ``None`` is the default (the
    slowest channel's). Raises :class:`~app.io.errors.InputError` as the whole read does for
    no usable channel, a raster channel not among them, spans that do not overlap, and a
    rate raster over ``max_rows`` rows or ``max_values`` values. A channel's raster is not
    held to those limits: its rows are recorded samples and the table is never built (the
    whole read refuses one over them, except when the channels share their timestamps)."""

    def __init__(
        self,
        file: SignalsFile,
        names: Sequence[str],
        units: Mapping[str, str],
        spans: Mapping[str, Span],
        raster: Raster | None,
        *,
        max_rows: int,
        max_values: int,
    ) -> None:
        if not file.recorded:
            raise ValueError("a dense dataset is read as stored (app.store.log_rows)")
        self.file = file
        wanted = set(names)
        chosen = [spans.get(name) for name, _ in file.channels if name in wanted]
        usable = [s for s in chosen if s is not None and s.start < s.stop]
        if not usable:
            raise InputError(
                "no channel has usable samples (at least 2 finite, valid samples each)",
                field="file",
            )
        start, stop, self.raster = plan_span(usable, raster or Raster())
        self.names = [s.name for s in usable]
        self.units = {name: units[name] for name in self.names}
        self.hold = [name in file.hold for name in self.names]
        self.stops = [s.stop for s in usable]  # each channel's last valid time
        self.fields = [file.time_name, *self.names]
        self.groups = file.reader.metadata.num_row_groups
        self.cache: OrderedDict[int, _Group] = OrderedDict()
        if self.raster.step is not None:
            grid = rate_grid(start, stop, self.raster.step, len(usable), max_rows, max_values)
            self._scan(None)
        else:
            own = self._scan(self.names.index(self.raster.channel or ""))
            grid = own[(own >= start) & (own <= stop)]
            del own
        self.grid = grid
        self.n = int(grid.size)
        self.step_s = None
        if self.n > 1:  # the whole read's median step; its copy is sorted in place
            self.step_s = float(np.median(np.diff(grid), overwrite_input=True))

    def rows(self, a: int, z: int) -> Signals:
        """Raster rows ``a … z−1``, made :data:`SPAN_GROUPS` stored row groups at a time, so
        a slow raster over fast channels never decodes a window's worth of stored rows at
        once."""
        a, z = max(0, a), min(self.n, z)
        grid = self.grid[a:z]
        channels = {name: np.empty(grid.size) for name in self.names}
        k = 0
        while k < grid.size:
            g = max(0, int(np.searchsorted(self.first_times, grid[k], side="right")) - 1)
            limit = self.last_times[min(g + SPAN_GROUPS, self.groups) - 1]
            end = max(k + 1, int(np.searchsorted(grid, limit, side="right")))
            part = grid[k:end]
            for track in self._tracks(float(part[0]), float(part[-1])):
                channels[track.name][k:end] = on_grid(track, track.time[track.valid], part)
            k = end
        return Signals(grid, channels, self.units, copy=False)

    def time(self) -> np.ndarray:
        """The raster's times (held whole: 8 bytes a row)."""
        return self.grid

    # -- reading ------------------------------------------------------------------------------

    def _scan(self, channel: int | None) -> np.ndarray:
        """One pass over the row groups: each one's first and last time, and per channel its
        first and last valid sample (NaN: none); returns the sample times of channel number
        ``channel`` (empty for ``None``)."""
        shape = (self.groups, len(self.names))
        self.first_times, self.last_times = np.empty(self.groups), np.empty(self.groups)
        self.first_valid = (np.full(shape, np.nan), np.full(shape, np.nan))  # (time, value)
        self.last_valid = (np.full(shape, np.nan), np.full(shape, np.nan))
        own = []
        for g in range(self.groups):
            group = self._group(g)
            time = group.time
            self.first_times[g], self.last_times[g] = time[0], time[-1]
            for c, (v, p) in enumerate(zip(group.values, group.present, strict=True)):
                valid = np.flatnonzero(p & np.isfinite(v))
                if valid.size:
                    i, j = valid[0], valid[-1]
                    self.first_valid[0][g, c], self.first_valid[1][g, c] = time[i], v[i]
                    self.last_valid[0][g, c], self.last_valid[1][g, c] = time[j], v[j]
                if c == channel:
                    own.append(time[p])
        return np.concatenate(own) if own else np.empty(0)

    def _tracks(self, first: float, last: float) -> list[Track]:
        """Each channel's samples from the row group of the last stored row at or before
        ``first`` to that of the first at or after ``last``; a channel with no valid sample
        at or before ``first`` there gets the last one before, and an interpolated channel
        with none at or after ``last`` (or its own last valid time, if earlier) the first one
        after, from the pass's notes."""
        g0 = max(0, int(np.searchsorted(self.first_times, first, side="right")) - 1)
        g1 = min(self.groups - 1, int(np.searchsorted(self.last_times, last, side="left")))
        parts = [self._group(g) for g in range(g0, g1 + 1)]
        time = np.concatenate([p.time for p in parts])
        tracks = []
        for c, name in enumerate(self.names):
            present = np.concatenate([p.present[c] for p in parts])
            t, v = time[present], np.concatenate([p.values[c] for p in parts])[present]
            valid_time = t[np.isfinite(v)]
            if valid_time.size == 0 or valid_time[0] > first:
                t, v = self._with(t, v, self._neighbour(c, range(g0 - 1, -1, -1), before=True))
            reach = min(last, self.stops[c])
            if not self.hold[c] and (valid_time.size == 0 or valid_time[-1] < reach):
                t, v = self._with(t, v, self._neighbour(c, range(g1 + 1, self.groups)))
            tracks.append(Track(name, self.units[name], t, v, self.hold[c]))
        return tracks

    def _neighbour(self, c: int, groups: range, *, before: bool = False) -> tuple[float, float]:
        """The valid sample of channel ``c`` nearest the part among ``groups`` (searched in
        their order): the last of the first group with one, before the part, or the first."""
        times, values = self.last_valid if before else self.first_valid
        for g in groups:
            if not np.isnan(times[g, c]):
                return float(times[g, c]), float(values[g, c])
        raise ArtifactCorruptError(
            f"channel {self.names[c]!r}: its span on the dataset's row does not match its samples"
        )

    @staticmethod
    def _with(
        t: np.ndarray, v: np.ndarray, sample: tuple[float, float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """``t``, ``v`` with ``sample`` added in time order."""
        at = int(np.searchsorted(t, sample[0]))
        return np.insert(t, at, sample[0]), np.insert(v, at, sample[1])

    def _group(self, g: int) -> _Group:
        if g in self.cache:
            self.cache.move_to_end(g)
            return self.cache[g]
        arrays, present = self._decode(g, self.fields)
        group = _Group(arrays[0], arrays[1:], present[1:])
        self.cache[g] = group
        while len(self.cache) > CACHED_GROUPS:
            self.cache.popitem(last=False)
        return group

    def _decode(self, g: int, fields: list[str]) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Row group ``g`` of ``fields``: the values (NaN where a channel has no sample) and
        the rows where each has one."""
        try:
            table = self.file.reader.read_row_group(g, columns=fields, use_threads=False)
            values, present = [], []
            for k in range(len(fields)):
                chunks = table.column(k).chunks
                chunk = chunks[0] if len(chunks) == 1 else pa.concat_arrays(chunks)
                rows = valid_rows(chunk)
                array = float64_values(chunk)
                if not rows.all():
                    if k == 0:
                        raise ValueError(f"the time column has {chunk.null_count} missing values")
                    array = np.where(rows, array, np.nan)
                values.append(array)
                present.append(rows)
            return values, present
        except (OSError, ValueError, pa.ArrowException) as exc:
            raise ArtifactCorruptError(f"row group {g} cannot be decoded: {exc}") from exc
