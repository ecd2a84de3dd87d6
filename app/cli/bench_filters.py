"""The map-filter sections of ``mapwise bench`` (:mod:`app.cli.bench`): the SKF paper's
Fig. 5 sweep over n×n tables, the 12×18 NOx table, compiled-for-4-corners against generic
kernels, and the SSKF product gain against the exact steady-state gain; and the test problem,
configs and kernel rates the peer comparisons (:mod:`app.cli.bench_peers`) share. Timing:
:mod:`app.cli.bench_timing`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from app.cli.bench_timing import rates
from estimation.filters.functions import run_chunk
from estimation.filters.state import FilterState
from estimation.kernels.gain_only import sskf_gain_1d
from estimation.registry import EstimatorKind, get_spec, names
from estimation.signals import Signals

FILTERS = names(EstimatorKind.MAP_FILTER)
NOX_SPEED_RPM = [750, 780, 1000, 1250, 1500, 1750, 2000, 2500, 3000, 3500, 4000, 4500]
NOX_FUEL_MG = [0, 5, 10, 15, 20, 25, 30, 34, 38, 42, 46, 50, 55, 60, 65, 70, 75, 80]
TARGET_SECONDS = 0.25  # wall time per measurement
DRIVE_STEP = 0.004  # operating-point step per sample, fraction of the axis range (σ)


def problem(
    n1: int, n2: int, samples: int, seed: int, *, uniform: bool = False
) -> tuple[Signals, dict[str, Any]]:
    """Inputs over an n1×n2 grid spanning [0, 1]² and a smooth true map plus noise.

    By default the operating point moves like a 50 Hz log of an aggressive drive: a
    reflected random walk with σ = 0.4 % of each axis range per sample (≈ 16 rpm per sample
    on a 4000 rpm axis). With ``uniform``, every sample is drawn anew over the grid (the SKF
    paper's simulation 1), so the active cell changes on nearly every sample: the worst case.
    """
    rng = np.random.default_rng(seed)
    if uniform:
        u = rng.uniform(0.0, 1.0, size=(samples, 2))
    else:
        steps = rng.normal(0.0, DRIVE_STEP, size=(samples, 2))
        u = np.abs((np.cumsum(steps, axis=0) + 0.5) % 2.0 - 1.0)  # reflect into [0, 1]
    y = np.sin(3.0 * u[:, 0]) + u[:, 1] ** 2 + rng.normal(0.0, 0.05, samples)
    signals = Signals(np.arange(samples) * 0.02, {"u1": u[:, 0], "u2": u[:, 1], "y": y})
    config = {
        "axes": [
            {"name": "u1", "breakpoints": np.linspace(0, 1, n1).tolist()},
            {"name": "u2", "breakpoints": np.linspace(0, 1, n2).tolist()},
        ],
        "output": "y",
    }
    return signals, config


def config_for(name: str, base: dict[str, Any], *, sensor: bool = False) -> dict[str, Any]:
    """Filter ``name``'s settings on a :func:`problem` config (``sensor``: with a NOx-like
    sensor model, a = 0.96 and a 38-sample delay)."""
    config = dict(base)
    if name in ("kf", "skf"):
        config |= {"sigma_w": 0.01, "sigma_v": 0.05, "p0": 1.0}
        if sensor:
            config["sensor"] = {"lag": 0.96, "delay_samples": 38, "sigma_f": 0.05}
    elif name == "sskf":
        config |= {"sigma_w": 0.01, "sigma_v": 0.05}
    return config


def filter_rate(
    name: str,
    signals: Signals,
    config: dict[str, Any],
    *,
    end_to_end: bool = True,
    generic: bool = True,
) -> dict[str, Any]:
    """Samples/s of the filter kernel alone (compiled for the table's corner count, and the
    generic kernel on the same inputs) and end to end (regressor + kernel + snapshot)."""
    estimator = get_spec(name).build(config)
    prepared = estimator.prepare(signals)
    state: FilterState = estimator.initial_state(prepared)
    n = prepared.y.size

    def kernel(specialised: bool = True) -> object:
        return run_chunk(
            state,
            prepared.idx,
            prepared.w,
            prepared.y,
            prepared.accept,
            prepared.settings,
            specialised=specialised,
        )

    changes = np.any(prepared.idx[1:] != prepared.idx[:-1], axis=1)
    out = {
        "kernel": rates(kernel, n),
        "cell_change_rate": float(np.mean(changes)) if n > 1 else 0.0,
    }
    if generic:
        out["generic_kernel"] = rates(lambda: kernel(False), n)
    if end_to_end:
        out["end_to_end"] = rates(lambda: estimator.fit(signals), len(signals))
    return out


def samples_for(name: str, p: int, quick: bool) -> int:
    """Enough samples for ~TARGET_SECONDS of work (the full KF costs O(p²) per sample)."""
    if name == "kf":
        estimate = int(TARGET_SECONDS / (2.5e-9 * p * p + 2e-8))
        return max(500, min(estimate, 400_000)) // (4 if quick else 1)
    return 200_000 if quick else 1_000_000


def sweep(sizes: list[int], quick: bool) -> list[dict[str, Any]]:
    rows = []
    for n in sizes:
        p = n * n
        row: dict[str, Any] = {"n": n, "p": p, "samples_per_s": {}, "relative_time": {}}
        for name in FILTERS:
            signals, base = problem(n, n, samples_for(name, p, quick), seed=n)
            rate = filter_rate(
                name, signals, config_for(name, base), end_to_end=False, generic=False
            )
            row["samples_per_s"][name] = rate["kernel"]["cpu_median"]
            row["cell_change_rate"] = rate["cell_change_rate"]
        sskf = row["samples_per_s"]["sskf"]
        row["relative_time"] = {k: sskf / v for k, v in row["samples_per_s"].items()}
        row["paper_relative_time"] = {"skf": 1.15, "kf": 0.82 * math.exp(0.0087 * p)}
        rows.append(row)
    return rows


def nox_table(quick: bool) -> dict[str, Any]:
    """Every filter on the 12×18 NOx table (drive-like inputs), plain and with the sensor
    model, and SKF on uniform inputs. The full KF runs from P0 for a few thousand samples here
    (P mostly zero, so flattered); :func:`full_kf` times it at steady state."""
    samples = 200_000 if quick else 1_000_000
    signals, base = problem(len(NOX_SPEED_RPM), len(NOX_FUEL_MG), samples, seed=34)
    base["axes"][0]["breakpoints"] = np.linspace(0, 1, len(NOX_SPEED_RPM)).tolist()
    out: dict[str, Any] = {"shape": [len(NOX_SPEED_RPM), len(NOX_FUEL_MG)], "filters": {}}
    for name in FILTERS:
        n = samples if name != "kf" else samples_for("kf", 216, quick)
        label = name if name != "kf" else "kf (from P0)"
        out["filters"][label] = filter_rate(name, signals.slice(0, n), config_for(name, base))
    for name in ("kf", "skf"):
        n = samples if name != "kf" else samples_for("kf", 217, quick)
        label = f"{name}+sensor" + (" (from P0)" if name == "kf" else "")
        out["filters"][label] = filter_rate(
            name, signals.slice(0, n), config_for(name, base, sensor=True)
        )
    uniform, _ = problem(len(NOX_SPEED_RPM), len(NOX_FUEL_MG), samples, seed=35, uniform=True)
    out["filters"]["skf, uniform inputs"] = filter_rate("skf", uniform, config_for("skf", base))
    return out


SPECIALISATION_SHAPES = ((2, 2), (12, 18), (21, 21))


def specialisation(quick: bool) -> dict[str, Any]:
    """The kernels compiled for 4 corners against the generic ones, on 2×2, 12×18 and 21×21
    tables, with drive-like and uniform inputs (the same log for every filter), and the ratios
    the kernels are held to: SKF/SSKF time per table and input, and 21×21 / 2×2 time per filter
    and input (cost flat in table size)."""
    samples = 200_000 if quick else 1_000_000
    rows: list[dict[str, Any]] = []
    for uniform in (False, True):
        for n1, n2 in SPECIALISATION_SHAPES:
            signals, base = problem(n1, n2, samples, seed=34, uniform=uniform)
            for name in ("skf", "sskf", "rls", "nlms"):
                rate = filter_rate(name, signals, config_for(name, base), end_to_end=False)
                rows.append(
                    {
                        "filter": name,
                        "shape": [n1, n2],
                        "inputs": "uniform" if uniform else "drive",
                        "specialised": rate["kernel"],
                        "generic": rate["generic_kernel"],
                        "cell_change_rate": rate["cell_change_rate"],
                    }
                )

    def cpu(name: str, shape: tuple[int, int], inputs: str) -> float:
        row = next(
            r
            for r in rows
            if (r["filter"], tuple(r["shape"]), r["inputs"]) == (name, shape, inputs)
        )
        return float(row["specialised"]["cpu_median"])

    inputs = ("drive", "uniform")
    return {
        "rows": rows,
        "skf_over_sskf_time": {
            f"{i} {a}x{b}": cpu("sskf", (a, b), i) / cpu("skf", (a, b), i)
            for i in inputs
            for a, b in SPECIALISATION_SHAPES
        },
        "largest_over_smallest_time": {
            f"{name} {i}": cpu(name, (2, 2), i) / cpu(name, (21, 21), i)
            for name in ("skf", "sskf", "rls", "nlms")
            for i in inputs
        },
    }


def sskf_gain_gap(r: float = 1.0, points: int = 11) -> dict[str, Any]:
    """Largest difference between the SSKF product gain (SKF (15)) and the exact steady-state
    gain of the 4-element local Riccati recursion over an η1×η2 grid (σw² = 1, σv² = r)."""
    worst = 0.0
    worst_at = (0.0, 0.0)
    for e1 in np.linspace(0.0, 1.0, points):
        for e2 in np.linspace(0.0, 1.0, points):
            q = np.array([(1 - e1) * (1 - e2), (1 - e1) * e2, e1 * (1 - e2), e1 * e2])
            product = np.array(
                [
                    sskf_gain_1d(e1, r) * sskf_gain_1d(e2, r),
                    sskf_gain_1d(e1, r) * sskf_gain_1d(1 - e2, r),
                    sskf_gain_1d(1 - e1, r) * sskf_gain_1d(e2, r),
                    sskf_gain_1d(1 - e1, r) * sskf_gain_1d(1 - e2, r),
                ]
            )
            gap = float(np.max(np.abs(product - exact_steady_gain(q, r))))
            if gap > worst:
                worst, worst_at = gap, (float(e1), float(e2))
    return {"r": r, "max_abs_gain_difference": worst, "at_eta": list(worst_at)}


def exact_steady_gain(q: np.ndarray, r: float, *, tol: float = 1e-13) -> np.ndarray:
    """Steady-state Kalman gain of ``x_k = x_{k−1} + w``, ``y = qᵀx + v`` (σw² = 1, σv² = r),
    by iterating the Riccati recursion to its fixed point."""
    P = np.zeros((q.size, q.size))
    gain = np.zeros(q.size)
    for _ in range(200_000):
        P = P + np.eye(q.size)
        Pq = P @ q
        new_gain = Pq / (q @ Pq + r)
        P = P - np.outer(new_gain, Pq)
        if np.max(np.abs(new_gain - gain)) < tol:
            return new_gain
        gain = new_gain
    return gain
