"""Reduce long series for plotting without losing their peaks."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np


def minmax_decimate(
    time: np.ndarray, channels: Mapping[str, np.ndarray], points: int
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """At most ``points`` samples on a shared time base, keeping each bucket's extremes.

    The log is cut into ``points // 2`` buckets; each contributes two samples at its first
    and last time, carrying every channel's minimum and maximum in the order they occur,
    so spikes survive (the time of an extreme moves by less than one bucket). NaN and ±Inf
    are skipped; a bucket with no finite value gives NaN twice. Of equal extremes the first
    counts. Decimating a decimated series again keeps the same extremes (the minimum of
    minima is the minimum), so storage and serving may both decimate.

    Vectorised per channel: bucket extremes by ``np.minimum.reduceat`` /
    ``np.maximum.reduceat``, their first positions by a second ``reduceat`` over the sample
    indices where a sample equals its bucket's extreme (O(n) with no Python loop per bucket).
    """
    n = time.size
    if n <= points or points < 2:
        return time.copy(), {k: np.asarray(v).copy() for k, v in channels.items()}
    buckets = points // 2
    # n > points ≥ 2·buckets, so every bucket holds at least two samples.
    edges = np.linspace(0, n, buckets + 1).astype(np.int64)
    starts, stops = edges[:-1], edges[1:]
    sizes = stops - starts
    out_time = np.empty(2 * buckets)
    out_time[0::2] = time[starts]
    out_time[1::2] = time[stops - 1]
    index = np.arange(n)
    out: dict[str, np.ndarray] = {}
    for name, values in channels.items():
        v = np.asarray(values, dtype=np.float64)
        finite = np.isfinite(v)
        lo = np.minimum.reduceat(np.where(finite, v, np.inf), starts)
        hi = np.maximum.reduceat(np.where(finite, v, -np.inf), starts)
        empty = np.add.reduceat(finite.astype(np.int64), starts) == 0
        at_lo = finite & (v == np.repeat(lo, sizes))
        at_hi = finite & (v == np.repeat(hi, sizes))
        i_lo = np.minimum.reduceat(np.where(at_lo, index, n), starts)
        i_hi = np.minimum.reduceat(np.where(at_hi, index, n), starts)
        lo_first = empty | (i_lo <= i_hi)
        lo[empty] = np.nan
        hi[empty] = np.nan
        pair = np.empty(2 * buckets)
        pair[0::2] = np.where(lo_first, lo, hi)
        pair[1::2] = np.where(lo_first, hi, lo)
        out[name] = pair
    return out_time, out


def stride_decimate(n: int, points: int) -> np.ndarray:
    """Indices of at most ``points`` evenly spread samples of ``n``, first and last kept."""
    if n <= points:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, points).round().astype(np.int64))


def finite_or_none(values: np.ndarray) -> list[float | None]:
    """JSON has no NaN/Inf: they become ``null``."""
    arr = np.asarray(values, dtype=np.float64)
    out: list[float | None] = arr.tolist()
    if not np.all(np.isfinite(arr)):
        for i in np.flatnonzero(~np.isfinite(arr)):
            out[i] = None
    return out


def nested_or_none(values: np.ndarray | None) -> list | None:
    """A table-shaped array as nested lists, NaN/Inf as ``null``."""
    if values is None:
        return None
    arr = np.asarray(values, dtype=np.float64)
    if np.all(np.isfinite(arr)):
        return arr.tolist()
    obj = arr.astype(object)
    obj[~np.isfinite(arr)] = None
    return obj.tolist()


class MinMaxBuckets:
    """:func:`minmax_decimate` of series that come a piece at a time, in order: the same
    buckets (fixed by the whole length ``n``, known first), the same extremes and the same
    times, without holding the series (a streamed run's stored series,
    ``tests/app/io/test_decimate.py`` holds the two equal)."""

    def __init__(self, n: int, points: int, names: list[str]) -> None:
        self.n, self.names = n, list(names)
        self.whole = n <= points or points < 2
        self.pieces: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
        buckets = points // 2
        edges = np.linspace(0, n, buckets + 1).astype(np.int64)
        self.starts, self.stops = edges[:-1], edges[1:]
        self.time = np.full(2 * buckets, np.nan)
        self.lo = {k: np.full(buckets, np.inf) for k in self.names}
        self.hi = {k: np.full(buckets, -np.inf) for k in self.names}
        self.i_lo = {k: np.full(buckets, n, dtype=np.int64) for k in self.names}
        self.i_hi = {k: np.full(buckets, n, dtype=np.int64) for k in self.names}
        self.finite = {k: np.zeros(buckets, dtype=np.int64) for k in self.names}
        self.seen = 0

    def add(self, time: np.ndarray, channels: Mapping[str, np.ndarray]) -> None:
        """The next samples ``seen … seen + len(time) − 1``, every channel of ``names``."""
        a, z = self.seen, self.seen + time.size
        self.seen = z
        if self.whole:
            self.pieces.append(
                (time.copy(), {k: np.asarray(channels[k]).copy() for k in self.names})
            )
            return
        if z == a:
            return
        first = int(np.searchsorted(self.stops, a, side="right"))
        last = int(np.searchsorted(self.starts, z, side="left"))  # buckets first … last − 1
        b = np.arange(first, last)
        at = np.maximum(self.starts[b], a) - a  # where each bucket's part of the piece starts
        sizes = np.minimum(self.stops[b], z) - a - at
        for edge, slot in ((self.starts[b], 0), (self.stops[b] - 1, 1)):
            inside = (edge >= a) & (edge < z)
            self.time[2 * b[inside] + slot] = time[edge[inside] - a]
        index = np.arange(a, z)
        for name in self.names:
            v = np.asarray(channels[name], dtype=np.float64)
            finite = np.isfinite(v)
            lo = np.minimum.reduceat(np.where(finite, v, np.inf), at)
            hi = np.maximum.reduceat(np.where(finite, v, -np.inf), at)
            i_lo = np.minimum.reduceat(
                np.where(finite & (v == np.repeat(lo, sizes)), index, self.n), at
            )
            i_hi = np.minimum.reduceat(
                np.where(finite & (v == np.repeat(hi, sizes)), index, self.n), at
            )
            self.finite[name][b] += np.add.reduceat(finite.astype(np.int64), at)
            lower = lo < self.lo[name][b]  # an equal extreme later in the bucket does not count
            self.lo[name][b] = np.where(lower, lo, self.lo[name][b])
            self.i_lo[name][b] = np.where(lower, i_lo, self.i_lo[name][b])
            higher = hi > self.hi[name][b]
            self.hi[name][b] = np.where(higher, hi, self.hi[name][b])
            self.i_hi[name][b] = np.where(higher, i_hi, self.i_hi[name][b])

    def result(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """What :func:`minmax_decimate` gives for the whole series (all ``n`` samples added)."""
        if self.seen != self.n:
            raise ValueError(f"{self.seen} of {self.n} samples added")
        if self.whole:
            if not self.pieces:
                return np.empty(0), {k: np.empty(0) for k in self.names}
            times, values = zip(*self.pieces, strict=True)
            return np.concatenate(times), {
                k: np.concatenate([v[k] for v in values]) for k in self.names
            }
        out: dict[str, np.ndarray] = {}
        for name in self.names:
            empty = self.finite[name] == 0
            lo, hi = self.lo[name].copy(), self.hi[name].copy()
            lo_first = empty | (self.i_lo[name] <= self.i_hi[name])
            lo[empty] = np.nan
            hi[empty] = np.nan
            pair = np.empty(2 * lo.size)
            pair[0::2] = np.where(lo_first, lo, hi)
            pair[1::2] = np.where(lo_first, hi, lo)
            out[name] = pair
        return self.time.copy(), out
