"""The measurements of ``mapwise bench``, one function per section (:mod:`app.cli.bench`).

Throughput is the best of several repeats after a warm-up (numba compiled), one core.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from estimation.filters.functions import run_chunk
from estimation.filters.settings import grid_of, resolve_settings
from estimation.filters.state import FilterState
from estimation.kernels.gain_only import sskf_gain_1d
from estimation.registry import EstimatorKind, get_spec, names
from estimation.signals import Signals

FILTERS = names(EstimatorKind.MAP_FILTER)
NOX_SPEED_RPM = [750, 780, 1000, 1250, 1500, 1750, 2000, 2500, 3000, 3500, 4000, 4500]
NOX_FUEL_MG = [0, 5, 10, 15, 20, 25, 30, 34, 38, 42, 46, 50, 55, 60, 65, 70, 75, 80]
TARGET_SECONDS = 0.25  # wall time per measurement


DRIVE_STEP = 0.004  # operating-point step per sample, fraction of the axis range (σ)


def _problem(
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


def _config_for(name: str, base: dict[str, Any], *, sensor: bool = False) -> dict[str, Any]:
    config = dict(base)
    if name in ("kf", "skf"):
        config |= {"sigma_w": 0.01, "sigma_v": 0.05, "p0": 1.0}
        if sensor:
            config["sensor"] = {"lag": 0.96, "delay_samples": 38, "sigma_f": 0.05}
    elif name == "sskf":
        config |= {"sigma_w": 0.01, "sigma_v": 0.05}
    return config


def _best_rate(run: Callable[[], object], samples: int, repeats: int = 3) -> float:
    run()  # warm-up: compile and fault in memory
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - t0)
    return samples / best


def _filter_rate(name: str, signals: Signals, config: dict[str, Any]) -> dict[str, float]:
    """Samples/s of the filter kernel alone and end to end (regressor + kernel + snapshot)."""
    estimator = get_spec(name).build(config)
    prepared = estimator.prepare(signals)
    state: FilterState = estimator.initial_state(prepared)
    n = prepared.y.size

    def kernel() -> object:
        return run_chunk(
            state, prepared.idx, prepared.w, prepared.y, prepared.accept, prepared.settings
        )

    def end_to_end() -> object:
        return estimator.fit(signals)

    changes = np.any(prepared.idx[1:] != prepared.idx[:-1], axis=1)
    return {
        "kernel_samples_per_s": _best_rate(kernel, n),
        "end_to_end_samples_per_s": _best_rate(end_to_end, len(signals)),
        "cell_change_rate": float(np.mean(changes)) if n > 1 else 0.0,
    }


def _samples_for(name: str, p: int, quick: bool) -> int:
    """Enough samples for ~TARGET_SECONDS of work (the full KF costs O(p²) per sample)."""
    if name == "kf":
        estimate = int(TARGET_SECONDS / (2.5e-9 * p * p + 2e-8))
        return max(500, min(estimate, 400_000)) // (4 if quick else 1)
    return 200_000 if quick else 2_000_000


def sweep(sizes: list[int], quick: bool) -> list[dict[str, Any]]:
    rows = []
    for n in sizes:
        p = n * n
        row: dict[str, Any] = {"n": n, "p": p, "samples_per_s": {}, "relative_time": {}}
        for name in FILTERS:
            signals, base = _problem(n, n, _samples_for(name, p, quick), seed=n)
            rate = _filter_rate(name, signals, _config_for(name, base))
            row["samples_per_s"][name] = rate["kernel_samples_per_s"]
            row["cell_change_rate"] = rate["cell_change_rate"]
        sskf = row["samples_per_s"]["sskf"]
        row["relative_time"] = {k: sskf / v for k, v in row["samples_per_s"].items()}
        row["paper_relative_time"] = {"skf": 1.15, "kf": 0.82 * math.exp(0.0087 * p)}
        rows.append(row)
    return rows


def nox_table(quick: bool) -> dict[str, Any]:
    samples = 200_000 if quick else 2_000_000
    signals, base = _problem(len(NOX_SPEED_RPM), len(NOX_FUEL_MG), samples, seed=34)
    base["axes"][0]["breakpoints"] = np.linspace(0, 1, len(NOX_SPEED_RPM)).tolist()
    out: dict[str, Any] = {"shape": [len(NOX_SPEED_RPM), len(NOX_FUEL_MG)], "filters": {}}
    for name in FILTERS:
        n = samples if name != "kf" else _samples_for("kf", 216, quick)
        sig = signals.slice(0, n)
        out["filters"][name] = _filter_rate(name, sig, _config_for(name, base))
    for name in ("kf", "skf"):
        n = samples if name != "kf" else _samples_for("kf", 217, quick)
        sig = signals.slice(0, n)
        out["filters"][f"{name}+sensor"] = _filter_rate(
            name, sig, _config_for(name, base, sensor=True)
        )
    uniform, _ = _problem(len(NOX_SPEED_RPM), len(NOX_FUEL_MG), samples, seed=35, uniform=True)
    out["filters"]["skf, uniform inputs"] = _filter_rate("skf", uniform, _config_for("skf", base))
    return out


def filterpy_comparison(n: int, samples: int) -> dict[str, Any]:
    """Our full KF vs FilterPy's ``KalmanFilter`` (dense predict/update, Joseph form)."""
    try:
        from filterpy.kalman import KalmanFilter
    except ImportError:
        return {"available": False, "note": "pip install filterpy to compare"}
    signals, base = _problem(n, n, samples, seed=16)
    config = _config_for("kf", base)
    estimator = get_spec("kf").build(config)
    prepared = estimator.prepare(signals)
    settings = resolve_settings(estimator.config, grid_of(estimator.config))
    p = n * n
    H = np.zeros((samples, p))
    np.put_along_axis(H, prepared.idx, prepared.w, axis=1)

    def filterpy_run() -> np.ndarray:
        kf = KalmanFilter(dim_x=p, dim_z=1)
        kf.x = np.zeros((p, 1))
        kf.P = np.diag(settings.p0)
        kf.F = np.eye(p)
        kf.Q = np.diag(settings.sigma_w2)
        kf.R = np.array([[settings.sigma_v2]])
        for k in range(samples):
            kf.predict()
            kf.update(prepared.y[k], H=H[k : k + 1])
        return kf.x.ravel()

    t0 = time.perf_counter()
    theirs = filterpy_run()
    filterpy_rate = samples / (time.perf_counter() - t0)
    ours = estimator.fit(signals).table.flat  # type: ignore[union-attr]
    mapwise_rate = _filter_rate("kf", signals, config)["kernel_samples_per_s"]
    diff = float(np.max(np.abs(ours - theirs)))
    return {
        "available": True,
        "n": n,
        "p": p,
        "samples": samples,
        "filterpy_samples_per_s": filterpy_rate,
        "mapwise_samples_per_s": mapwise_rate,
        "speedup": mapwise_rate / filterpy_rate,
        "max_abs_map_difference": diff,
        "same_map": bool(diff <= 1e-8 * max(1.0, float(np.max(np.abs(theirs))))),
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


def simulators() -> dict[str, dict[str, float]]:
    """Wall time of each ground-truth generator over a full record (compiled, best of 3)."""
    from estimation.cycles import load_cycle
    from estimation.plants.airpath import simulate_airpath
    from estimation.plants.nox import simulate_nox
    from estimation.plants.torque import simulate_si_torque
    from estimation.plants.vehicle import operating_points

    wltc = load_cycle("wltc3b")
    points = operating_points(wltc, rate_hz=50.0)
    fuel = np.minimum(points.fuel_mg_per_cycle, 56.0)
    speed = np.minimum(points.speed_rpm, 3000.0)
    cases: dict[str, tuple[Callable[[], object], float, float]] = {
        "vehicle model, WLTC 1800 s at 50 Hz": (
            lambda: operating_points(wltc, rate_hz=50.0), wltc.duration_s, 50.0
        ),
        "air path, WLTC 1800 s, 2 kHz internal": (
            lambda: simulate_airpath(points.time_s, fuel, speed, seed=0, rate_hz=10.0),
            float(points.time_s[-1]), 2000.0,
        ),
        "NOx sensor, 1800 s at 50 Hz": (
            lambda: simulate_nox(points.time_s, speed, fuel, seed=0),
            float(points.time_s[-1]), 50.0,
        ),
        "SI torque, 30 s, 10 kHz internal": (
            lambda: simulate_si_torque(seed=0), 30.0, 10_000.0
        ),
    }  # fmt: skip
    out = {}
    for name, (run, seconds, rate) in cases.items():
        run()
        best = min(_timed(run) for _ in range(3))
        out[name] = {"simulated_s": seconds, "internal_rate_hz": rate, "wall_s": best}
    return out


def estimators_on_scenarios(quick: bool) -> dict[str, dict[str, float]]:
    """End-to-end samples/s (``fit`` over the whole record) of the non-table estimators on
    their scenarios."""
    from estimation.scenarios import get_scenario

    out = {}
    for scenario in ("torque-si", "torque-rig"):
        data = get_scenario(scenario).build(seed=0, duration_s=10.0 if quick else None)
        for name in names(EstimatorKind.TORQUE):
            config = get_scenario(scenario).default_config(name)
            estimator = get_spec(name).build(config)
            signals = data.signals
            rate = _best_rate(lambda e=estimator, s=signals: e.fit(s), len(signals))
            out[f"{name} on {scenario}"] = {"samples_per_s": rate}
    return out


def observers_on_scenarios(quick: bool) -> dict[str, dict[str, float]]:
    """The observers over a whole cycle (seed 0): LPV (LPV (26)) on ``maf-whtc``, the EKF
    variants (EKF §5.1) on ``maf-1d-whtc``.

    ``kernel_samples_per_s`` is the compiled observer alone from the initial state over the
    whole log (:func:`lpv_run`, :func:`ekf_run`); ``fit_s`` the end-to-end ``fit`` (prepare,
    LMI gain design or initial settling, kernel, snapshot) in seconds; for LPV ``design_s``
    is the LMI gain synthesis alone (cvxpy + Clarabel, LPV (28)/(35)). Best of 3 after a
    warm-up; ``quick`` uses the first 300 s.
    """
    from estimation.observers.ekf import ekf_run
    from estimation.observers.lpv import lpv_run
    from estimation.scenarios import get_scenario

    duration = 300.0 if quick else None
    out: dict[str, dict[str, float]] = {}

    scenario = get_scenario("maf-whtc")
    signals = scenario.build(seed=0, duration_s=duration).signals
    lpv = get_spec("lpv").build(scenario.default_config("lpv"))
    prepared = lpv.prepare(signals)
    start = lpv.initial_state(signals, prepared)  # type: ignore[union-attr]
    n = len(signals)

    def lpv_kernel() -> object:
        return lpv_run(
            start, prepared, 0, n, gamma=lpv.config.gamma, adaptation=lpv.config.adaptation
        )

    fit_rate = _best_rate(lambda: lpv.fit(signals), n)
    out["lpv on maf-whtc"] = {
        "samples": n,
        "kernel_samples_per_s": _best_rate(lpv_kernel, n),
        "fit_samples_per_s": fit_rate,
        "fit_s": n / fit_rate,
        "design_s": _best_time(lambda: lpv.design_gain(signals)),
    }

    scenario = get_scenario("maf-1d-whtc")
    signals = scenario.build(seed=0, duration_s=duration).signals
    n = len(signals)
    for name in names(EstimatorKind.JOINT_EKF):
        ekf = get_spec(name).build(scenario.default_config(name))
        model = ekf.prepare(signals)
        state = ekf.initial_state(model)  # type: ignore[union-attr]

        def ekf_kernel(e: Any = ekf, m: Any = model, s0: Any = state) -> object:
            return ekf_run(s0, m, e.settings, n)

        fit_rate = _best_rate(lambda e=ekf: e.fit(signals), n)
        out[f"{name} on maf-1d-whtc"] = {
            "samples": n,
            "kernel_samples_per_s": _best_rate(ekf_kernel, n),
            "fit_samples_per_s": fit_rate,
            "fit_s": n / fit_rate,
        }
    return out


def _best_time(run: Callable[[], object], repeats: int = 3) -> float:
    run()  # warm-up
    return min(_timed(run) for _ in range(repeats))


def _timed(run: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    run()
    return time.perf_counter() - t0
