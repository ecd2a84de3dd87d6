"""``minmax_decimate``: the vectorised decimator agrees with a plain per-bucket loop (the
reference below, the original implementation) on random, tied, NaN/Inf-laden and spiky
data, and keeps its contract (at most ``points`` samples, bucket edges as times)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from app.io.decimate import MinMaxBuckets, minmax_decimate


def slow_minmax(time: np.ndarray, values: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """Reference: per bucket, the first minimum and the first maximum of the finite values
    in the order they occur, at the bucket's first and last time; NaN twice if none."""
    n = time.size
    if n <= points or points < 2:
        return time.copy(), np.asarray(values, dtype=np.float64).copy()
    buckets = points // 2
    edges = np.linspace(0, n, buckets + 1).astype(np.int64)
    t_out, v_out = [], []
    for a, z in itertools.pairwise(edges):
        t_out += [time[a], time[z - 1]]
        seg = [(i, float(values[i])) for i in range(a, z) if np.isfinite(values[i])]
        if not seg:
            v_out += [np.nan, np.nan]
            continue
        i_lo = min(seg, key=lambda p: (p[1], p[0]))[0]
        i_hi = max(seg, key=lambda p: (p[1], -p[0]))[0]
        first, second = (i_lo, i_hi) if i_lo <= i_hi else (i_hi, i_lo)
        v_out += [float(values[first]), float(values[second])]
    return np.array(t_out), np.array(v_out)


def _cases() -> list[tuple[str, np.ndarray]]:
    rng = np.random.default_rng(7)
    n = 10_007
    noisy = rng.normal(size=n)
    tied = rng.integers(0, 3, n).astype(float)  # many equal extremes: the first must win
    holes = noisy.copy()
    holes[rng.random(n) < 0.3] = np.nan
    holes[rng.random(n) < 0.05] = np.inf
    holes[2000:2600] = np.nan  # whole buckets without a finite value
    spike = rng.normal(scale=0.01, size=n)
    spike[4321] = 64.7
    return [("noisy", noisy), ("tied", tied), ("holes", holes), ("spike", spike)]


@pytest.mark.parametrize("points", [2, 3, 4, 101, 1000, 4000, 10_006])
def test_matches_the_per_bucket_loop(points: int) -> None:
    cases = _cases()
    time = np.arange(cases[0][1].size) * 0.01
    got_t, got = minmax_decimate(time, dict(cases), points)
    for name, values in cases:
        ref_t, ref = slow_minmax(time, values, points)
        np.testing.assert_array_equal(got_t, ref_t)
        np.testing.assert_array_equal(got[name], ref, err_msg=name)
        assert got[name].size <= points


def test_a_single_spike_survives_and_short_series_pass_through() -> None:
    values = np.full(200_000, 0.5)
    values[123_457] = 64.7
    time = np.arange(values.size) / 1000.0
    t, out = minmax_decimate(time, {"e": values}, 4000)
    assert t.size == out["e"].size == 4000
    assert out["e"].max() == 64.7
    # where it occurred, to within one bucket (50 samples)
    assert abs(t[out["e"].argmax()] - time[123_457]) <= 50 / 1000.0
    # decimating again (storage, then serving) keeps the extreme
    _, again = minmax_decimate(t, out, 1500)
    assert again["e"].max() == 64.7

    short_t, short = minmax_decimate(time[:10], {"e": values[:10]}, 4000)
    np.testing.assert_array_equal(short_t, time[:10])
    np.testing.assert_array_equal(short["e"], values[:10])


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("points", [4, 7, 100, 4000, 10_000])
def test_buckets_filled_piece_by_piece_give_the_whole_decimation(seed: int, points: int) -> None:
    """Ties (coarse values), NaN, ±inf, all-NaN stretches and cuts anywhere, even inside a
    bucket and one sample long: the streamed decimation is the whole one, bit for bit."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 9000))
    time = np.cumsum(rng.uniform(0.001, 0.02, n))
    coarse = np.round(rng.normal(0, 2, n))
    coarse[rng.random(n) < 0.05] = np.nan
    coarse[rng.random(n) < 0.01] = rng.choice([np.inf, -np.inf])
    silent = np.full(n, np.nan)
    silent[: n // 3] = rng.normal(size=n // 3)
    series = {"coarse": coarse, "fine": rng.normal(size=n), "silent": silent}
    whole_time, whole = minmax_decimate(time, series, points)
    buckets = MinMaxBuckets(n, points, list(series))
    cuts = np.unique(np.concatenate([[0, n], rng.integers(0, n, int(rng.integers(0, 40)))]))
    cuts = np.unique(np.concatenate([cuts, [1, 2]])) if n > 2 else cuts
    for a, z in itertools.pairwise(cuts):
        buckets.add(time[a:z], {k: v[a:z] for k, v in series.items()})
    got_time, got = buckets.result()
    np.testing.assert_array_equal(got_time, whole_time)
    for name in series:
        np.testing.assert_array_equal(got[name], whole[name])
