"""A dataset stored as recorded, read a window at a time on a raster.

:class:`RasterRows` is the streamed counterpart of :func:`app.store.datasets.load_on_raster`
(`docs/data-formats.md#streamed-runs`). It plans the raster by the same rules
(:func:`app.io.resample.plan_span`), from the channels' spans that ingest keeps on the
dataset's row (:attr:`app.domain.Channel.timing`) instead of from a pass over the samples,
and holds only the raster's time column (8 bytes a row, as every streamed log does).

Row ``k`` of its raster equals row ``k`` of the whole read, bit for bit. A window decodes the
stored row groups that hold its span, widened until every channel has a valid sample at or
before the window's first time and, for a channel interpolated linearly, one at or after its
last. Zero-order hold reads only the previous valid sample, and ``numpy.interp`` only the two
valid samples around each time, so the other samples of the log are never needed.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from app.io.arrow_arrays import float64_values, valid_rows
from app.io.errors import InputError
from app.io.resample import Raster, Span, Track, check_size, on_grid, plan_span, rate_grid
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
    slowest channel's). Raises :class:`~app.io.errors.InputError` where the whole read
    would: no usable channel, a raster channel not among them, spans that do not overlap,
    a raster over ``max_rows`` rows or ``max_values`` values."""

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
        self.fields = [file.time_name, *self.names]
        meta = file.reader.metadata
        self.groups = meta.num_row_groups
        self.cache: OrderedDict[int, _Group] = OrderedDict()
        self.first_times, self.last_times = self._group_bounds()
        self.grid = self._grid(start, stop, len(usable), max_rows, max_values)
        self.n = int(self.grid.size)
        self.step_s = None
        if self.n > 1:  # the whole read's median step; its copy is sorted in place
            self.step_s = float(np.median(np.diff(self.grid), overwrite_input=True))

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
            time, values, present = self._around(float(part[0]), float(part[-1]))
            for name, hold, v, p in zip(self.names, self.hold, values, present, strict=True):
                track = Track(name, self.units[name], time[p], v[p], hold)
                channels[name][k:end] = on_grid(track, track.time[track.valid], part)
            k = end
        return Signals(grid, channels, self.units, copy=False)

    def time(self) -> np.ndarray:
        """The raster's times (held whole: 8 bytes a row)."""
        return self.grid

    # -- reading ------------------------------------------------------------------------------

    def _grid(
        self, start: float, stop: float, channels: int, max_rows: int, max_values: int
    ) -> np.ndarray:
        """The raster's times over ``[start, stop]``: a rate's, or the raster channel's
        sample times there."""
        if self.raster.step is not None:
            return rate_grid(start, stop, self.raster.step, channels, max_rows, max_values)
        own = self._present_times(self.raster.channel or "")
        grid = own[(own >= start) & (own <= stop)]
        check_size(grid.size, channels, self.raster, max_rows, max_values)
        return grid

    def _around(
        self, first: float, last: float
    ) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
        """The stored rows from the row group of the last row at or before ``first`` to that
        of the first row at or after ``last``, widened a group at a time until each channel
        has the valid neighbours its rule reads."""
        g0 = max(0, int(np.searchsorted(self.first_times, first, side="right")) - 1)
        g1 = min(self.groups - 1, int(np.searchsorted(self.last_times, last, side="left")))
        while True:
            parts = [self._group(g) for g in range(g0, g1 + 1)]
            time = np.concatenate([p.time for p in parts])
            values = [np.concatenate(c) for c in zip(*(p.values for p in parts), strict=True)]
            present = [np.concatenate(c) for c in zip(*(p.present for p in parts), strict=True)]
            before, after = True, True
            for hold, v, p in zip(self.hold, values, present, strict=True):
                valid_time = time[p & np.isfinite(v)]
                before &= valid_time.size > 0 and valid_time[0] <= first
                after &= hold or (valid_time.size > 0 and valid_time[-1] >= last)
            if before and after:
                return time, values, present
            if (not before and g0 == 0) or (not after and g1 == self.groups - 1):
                raise ArtifactCorruptError(
                    "the channels' spans on the dataset's row do not match its samples"
                )
            g0 -= 0 if before else 1
            g1 += 0 if after else 1

    def _group_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Each row group's first and last time."""
        first, last = np.empty(self.groups), np.empty(self.groups)
        for g in range(self.groups):
            time = self._decode(g, [self.file.time_name])[0][0]
            first[g], last[g] = time[0], time[-1]
        return first, last

    def _present_times(self, name: str) -> np.ndarray:
        """The times of the rows where channel ``name`` has a sample."""
        parts = []
        for g in range(self.groups):
            (time, _), (_, present) = self._decode(g, [self.file.time_name, name])
            parts.append(time[present])
        return np.concatenate(parts) if parts else np.empty(0)

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
