"""The model sections of ``mapwise bench`` (:mod:`app.cli.bench`): the ground-truth
simulators over a full record, the torque estimators end to end on their scenarios, and the
LPV and EKF observers over a whole cycle. Best of 3 wall-time runs after a warm-up
(:mod:`app.cli.bench_timing`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from app.cli.bench_timing import best_rate, best_time, timed
from estimation.registry import EstimatorKind, get_spec, names


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
        best = min(timed(run) for _ in range(3))
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
            rate = best_rate(lambda e=estimator, s=signals: e.fit(s), len(signals))
            out[f"{name} on {scenario}"] = {"samples_per_s": rate}
    return out


def _first_design_s(design: Callable[[], object]) -> float:
    from estimation.observers.lmi import forget_compiled_lmis

    def first() -> object:
        forget_compiled_lmis()
        return design()

    return best_time(first)


def observers_on_scenarios(quick: bool) -> dict[str, dict[str, float]]:
    """The observers over a whole cycle (seed 0): LPV (LPV (26)) on ``maf-whtc``, the EKF
    variants (EKF §5.1) on ``maf-1d-whtc``.

    ``kernel_samples_per_s`` is the compiled observer alone from the initial state over the
    whole log (:func:`lpv_run`, :func:`ekf_run`); ``fit_s`` the end-to-end ``fit`` (prepare,
    LMI gain design or initial settling, kernel, snapshot) in seconds; for LPV ``design_s``
    is the LMI gain synthesis (cvxpy + Clarabel, LPV (28)/(35)) with the ρ box it needs, once
    its problem is compiled, and ``first_design_s`` the first design of a process, which
    compiles it (best of 3, each after :func:`~estimation.observers.lmi.forget_compiled_lmis`); and
    ``rho_samples_per_s`` the scheduling vector ρ computed from the observer's model
    (``rho_source="model"``: the Seiliger fixed point per sample,
    :func:`~estimation.observers.airpath_model.model_rho`) rather than read from the log.
    Best of 3 after a warm-up; ``quick`` uses the first 300 s.
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

    fit_rate = best_rate(lambda: lpv.fit(signals), n)
    model_config = {**scenario.default_config("lpv"), "rho_source": "model"}
    model_lpv: Any = get_spec("lpv").build(model_config)
    out["lpv on maf-whtc"] = {
        "samples": n,
        "kernel_samples_per_s": best_rate(lpv_kernel, n),
        "fit_samples_per_s": fit_rate,
        "fit_s": n / fit_rate,
        "design_s": best_time(lambda: lpv.design_gain(signals)),
        "first_design_s": _first_design_s(lambda: lpv.design_gain(signals)),
        "rho_samples_per_s": best_rate(lambda: model_lpv.scheduling(signals), n),
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

        fit_rate = best_rate(lambda e=ekf: e.fit(signals), n)
        out[f"{name} on maf-1d-whtc"] = {
            "samples": n,
            "kernel_samples_per_s": best_rate(ekf_kernel, n),
            "fit_samples_per_s": fit_rate,
            "fit_s": n / fit_rate,
        }
    return out
