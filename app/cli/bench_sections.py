"""The measurements of ``mapwise bench``, one function per section (:mod:`app.cli.bench`).

Map-filter throughput is the median and the worst of :data:`REPEATS` runs after a warm-up
(numba compiled), in CPU time (``time.process_time``) and wall time, one core. The observer,
estimator and simulator sections report the best of 3 wall-time runs.
"""

from __future__ import annotations

import math
import os
import platform
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from app.cli import bench_numpy
from estimation.filters.functions import run_chunk
from estimation.filters.settings import FilterSettings
from estimation.filters.state import FilterState
from estimation.kernels.gain_only import sskf_gain_1d
from estimation.registry import EstimatorKind, get_spec, names
from estimation.signals import Signals

FILTERS = names(EstimatorKind.MAP_FILTER)
NOX_SPEED_RPM = [750, 780, 1000, 1250, 1500, 1750, 2000, 2500, 3000, 3500, 4000, 4500]
NOX_FUEL_MG = [0, 5, 10, 15, 20, 25, 30, 34, 38, 42, 46, 50, 55, 60, 65, 70, 75, 80]
TARGET_SECONDS = 0.25  # wall time per measurement
REPEATS = 5  # timed runs per map-filter measurement (median and worst reported)


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


def machine() -> dict[str, Any]:
    """The machine the figures come from: CPU model (``/proc/cpuinfo``), logical cores, the
    1/5/15-minute load average (on a shared machine the figures are only as quiet as that) and
    the BLAS threads FilterPy and the numpy references may use (``OPENBLAS_NUM_THREADS=1`` keeps
    every peer on one core, like the kernels)."""
    model = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            names = [
                line.split(":", 1)[1].strip() for line in cpuinfo if line.startswith("model name")
            ]
        model = names[0] if names else model
    except OSError:
        pass
    return {
        "python": platform.python_version(),
        "cpu_model": model,
        "cores": os.cpu_count(),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
    }


def _rates(run: Callable[[], object], samples: int, repeats: int = REPEATS) -> dict[str, float]:
    """Samples/s of ``run`` after one warm-up call: median and worst of ``repeats`` runs, in
    CPU time of this process and in wall time."""
    run()  # warm-up: compile and fault in memory
    cpu, wall = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        run()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return {
        "cpu_median": samples / float(np.median(cpu)),
        "cpu_worst": samples / max(cpu),
        "wall_median": samples / float(np.median(wall)),
        "wall_worst": samples / max(wall),
    }


def _filter_rate(
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
        "kernel": _rates(kernel, n),
        "cell_change_rate": float(np.mean(changes)) if n > 1 else 0.0,
    }
    if generic:
        out["generic_kernel"] = _rates(lambda: kernel(False), n)
    if end_to_end:
        out["end_to_end"] = _rates(lambda: estimator.fit(signals), len(signals))
    return out


def _samples_for(name: str, p: int, quick: bool) -> int:
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
            signals, base = _problem(n, n, _samples_for(name, p, quick), seed=n)
            rate = _filter_rate(
                name, signals, _config_for(name, base), end_to_end=False, generic=False
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
    signals, base = _problem(len(NOX_SPEED_RPM), len(NOX_FUEL_MG), samples, seed=34)
    base["axes"][0]["breakpoints"] = np.linspace(0, 1, len(NOX_SPEED_RPM)).tolist()
    out: dict[str, Any] = {"shape": [len(NOX_SPEED_RPM), len(NOX_FUEL_MG)], "filters": {}}
    for name in FILTERS:
        n = samples if name != "kf" else _samples_for("kf", 216, quick)
        label = name if name != "kf" else "kf (from P0)"
        out["filters"][label] = _filter_rate(name, signals.slice(0, n), _config_for(name, base))
    for name in ("kf", "skf"):
        n = samples if name != "kf" else _samples_for("kf", 217, quick)
        label = f"{name}+sensor" + (" (from P0)" if name == "kf" else "")
        out["filters"][label] = _filter_rate(
            name, signals.slice(0, n), _config_for(name, base, sensor=True)
        )
    uniform, _ = _problem(len(NOX_SPEED_RPM), len(NOX_FUEL_MG), samples, seed=35, uniform=True)
    out["filters"]["skf, uniform inputs"] = _filter_rate("skf", uniform, _config_for("skf", base))
    return out


DENSE = 0.9  # P counts as filled when this share of its entries is non-zero


def full_kf(n: int, quick: bool) -> dict[str, Any]:
    """The full KF on an n×n table, timed from P0 and at steady state, against the plain-numpy
    update (:func:`app.cli.bench_numpy.kf`) and FilterPy's ``KalmanFilter`` (dense
    predict/update, Joseph form) on the same samples.

    From P0 most of P is zero and the kernel skips zero rows of the rank-1 update, so it looks
    far faster than it is. Steady state is after a warm-up on the same drive log, run until
    at least :data:`DENSE` of P's entries are non-zero (or the warm-up budget runs out); every
    steady-state figure starts from that state. Each peer must give the kernel's map.
    """
    timed = 2_000 if quick else 10_000
    budget = 40_000 if quick else 200_000
    signals, base = _problem(n, n, budget + timed, seed=16)
    estimator = get_spec("kf").build(_config_for("kf", base))
    prepared = estimator.prepare(signals)
    settings = prepared.settings
    start = estimator.initial_state(prepared)

    def run(state: Any, first: int, count: int) -> Any:
        sl = slice(first, first + count)
        return run_chunk(
            state, prepared.idx[sl], prepared.w[sl], prepared.y[sl], prepared.accept[sl], settings
        )[0]

    from_p0 = _rates(lambda: run(start, 0, timed), timed)
    density_from_p0 = _density(run(start, 0, timed).P)
    warm, used = start, 0
    while used < budget and _density(warm.P) < DENSE:
        warm = run(warm, used, 5_000)
        used += 5_000
    steady = _rates(lambda: run(warm, used, timed), timed)

    n_numpy = 100 if quick else 500
    rows = slice(used, used + n_numpy)

    def numpy_kf() -> np.ndarray:
        return bench_numpy.kf(
            warm.theta, warm.P, prepared.idx[rows], prepared.w[rows], prepared.y[rows],
            sigma_w2=settings.sigma_w2, sigma_v2=settings.sigma_v2,
        )[0]  # fmt: skip

    numpy_rate = _rates(numpy_kf, n_numpy)
    out: dict[str, Any] = {
        "n": n,
        "p": n * n,
        "timed_samples": timed,
        "from_p0": {"samples_per_s": from_p0, "p_nonzero_after": density_from_p0},
        "steady_state": {
            "warm_up_samples": used,
            "p_nonzero": _density(warm.P),
            "samples_per_s": steady,
        },
        "numpy": {
            "samples": n_numpy,
            "samples_per_s": numpy_rate,
            "same_map": _same(run(warm, used, n_numpy).theta, numpy_kf()),
        },
    }
    out["filterpy"] = _filterpy_kf(warm, prepared, used, 20 if quick else 100)
    return out


def _filterpy_kf(warm: Any, prepared: Any, first: int, samples: int) -> dict[str, Any]:
    """FilterPy's ``KalmanFilter`` from the warm state over ``samples`` samples (its cost does
    not depend on how full P is)."""
    try:
        from filterpy.kalman import KalmanFilter
    except ImportError:
        return {"available": False, "note": "pip install filterpy to compare"}
    settings = prepared.settings
    p = warm.theta.size
    H = np.zeros((samples, p))
    sl = slice(first, first + samples)
    np.put_along_axis(H, prepared.idx[sl], prepared.w[sl], axis=1)
    y = prepared.y[sl]

    def filterpy_run() -> np.ndarray:
        kf = KalmanFilter(dim_x=p, dim_z=1)
        kf.x = warm.theta.reshape(p, 1).copy()
        kf.P = warm.P.copy()
        kf.F = np.eye(p)
        kf.Q = np.diag(settings.sigma_w2)
        kf.R = np.array([[settings.sigma_v2]])
        for k in range(samples):
            kf.predict()
            kf.update(y[k], H=H[k : k + 1])
        return kf.x.ravel()

    ours = run_chunk(warm, prepared.idx[sl], prepared.w[sl], y, prepared.accept[sl], settings)[
        0
    ].theta
    return {
        "available": True,
        "samples": samples,
        "samples_per_s": _rates(filterpy_run, samples),
        "same_map": _same(ours, filterpy_run()),
    }


def numpy_comparison(quick: bool) -> dict[str, Any]:
    """Each covariance-free or local filter against its plain-numpy update
    (:mod:`app.cli.bench_numpy`) on the 12×18 table and the same drive log: numpy over the
    log's first samples, the kernel over the whole log (too short a run times the call, not the
    kernel); both must give the same map over the first samples."""
    samples = 200_000 if quick else 1_000_000
    n_numpy = 500 if quick else 3_000
    signals, base = _problem(len(NOX_SPEED_RPM), len(NOX_FUEL_MG), samples, seed=34)
    out: dict[str, Any] = {"shape": [len(NOX_SPEED_RPM), len(NOX_FUEL_MG)], "filters": {}}
    for name in ("skf", "sskf", "rls", "nlms"):
        estimator = get_spec(name).build(_config_for(name, base))
        prepared = estimator.prepare(signals)
        settings = prepared.settings
        start = estimator.initial_state(prepared)
        sl = slice(0, n_numpy)
        idx, w, y = prepared.idx[sl], prepared.w[sl], prepared.y[sl]
        reference = partial(_numpy_reference, name, start.theta, idx, w, y, settings)
        ours = run_chunk(start, idx, w, y, prepared.accept[sl], settings)[0].theta
        kernel = _filter_rate(
            name, signals, _config_for(name, base), end_to_end=False, generic=False
        )
        numpy_rate = _rates(reference, n_numpy)
        out["filters"][name] = {
            "kernel": kernel["kernel"],
            "numpy": numpy_rate,
            "numpy_samples": n_numpy,
            "speedup_cpu": kernel["kernel"]["cpu_median"] / numpy_rate["cpu_median"],
            "same_map": _same(ours, reference()),
        }
    return out


def _numpy_reference(
    name: str, theta0: np.ndarray, idx: np.ndarray, w: np.ndarray, y: np.ndarray,
    settings: FilterSettings,
) -> np.ndarray:  # fmt: skip
    """The map after the plain-numpy update of filter ``name`` over ``idx, w, y``."""
    if name in ("skf", "rls"):
        rls = name == "rls"
        return bench_numpy.local(
            theta0, idx, w, y, p0=settings.p0,
            sigma_w2=np.zeros_like(settings.sigma_w2) if rls else settings.sigma_w2,
            r=1.0 if rls else settings.sigma_v2, forget=settings.forgetting if rls else 1.0,
        )  # fmt: skip
    if name == "sskf":
        return bench_numpy.sskf(
            theta0, idx, w, y, sigma_w2=settings.sigma_w2, sigma_v2=settings.sigma_v2
        )
    return bench_numpy.nlms(theta0, idx, w, y, mu=settings.mu, eps=settings.eps)


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
            signals, base = _problem(n1, n2, samples, seed=34, uniform=uniform)
            for name in ("skf", "sskf", "rls", "nlms"):
                rate = _filter_rate(name, signals, _config_for(name, base), end_to_end=False)
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


def _density(P: np.ndarray) -> float:
    return float(np.count_nonzero(P)) / P.size


def _same(ours: np.ndarray, theirs: np.ndarray) -> bool:
    """The same map up to rounding (different summation orders)."""
    return bool(np.allclose(ours, theirs, rtol=1e-9, atol=1e-9 * max(1.0, np.max(np.abs(theirs)))))


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
