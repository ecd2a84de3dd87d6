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
    so spikes survive (the time of an extreme moves by less than one bucket).
    """
    n = time.size
    if n <= points or points < 4:
        return time.copy(), {k: np.asarray(v).copy() for k, v in channels.items()}
    buckets = points // 2
    edges = np.linspace(0, n, buckets + 1).astype(np.int64)
    starts, stops = edges[:-1], edges[1:]
    out_time = np.empty(2 * buckets)
    out_time[0::2] = time[starts]
    out_time[1::2] = time[stops - 1]
    out: dict[str, np.ndarray] = {}
    for name, values in channels.items():
        v = np.asarray(values, dtype=np.float64)
        finite = np.where(np.isfinite(v), v, np.nan)
        lo = np.empty(buckets)
        hi = np.empty(buckets)
        lo_first = np.empty(buckets, dtype=bool)
        for b, (a, z) in enumerate(zip(starts, stops, strict=True)):
            seg = finite[a:z]
            if np.all(np.isnan(seg)):
                lo[b] = hi[b] = np.nan
                lo_first[b] = True
                continue
            i_lo, i_hi = int(np.nanargmin(seg)), int(np.nanargmax(seg))
            lo[b], hi[b], lo_first[b] = seg[i_lo], seg[i_hi], i_lo <= i_hi
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
