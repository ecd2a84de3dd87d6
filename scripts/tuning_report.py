"""The figures of docs/tuning.md: ``mapwise tune``'s σv against the true σv, and held-out
prediction error, on the held-out seeds 100–109 of the map-filter scenarios with known σv.

    .venv/bin/python scripts/tuning_report.py            # about 2 CPU-minutes

Prints Markdown tables. Nothing here is tuned on these seeds: the search and its starts are
those of estimation/tuning.py, the configs the scenarios' defaults (papers' settings, with
the estimator-side constants drawn under ``mismatch``).
"""

from __future__ import annotations

import math

import numpy as np

from estimation.holdout import holdout_error
from estimation.innovation import map_filter, run_innovations, stats_of
from estimation.plants.synthetic import SIM3_NOISE_AMPLITUDE
from estimation.scenarios import ScenarioData, get_scenario
from estimation.tuning import tune, with_settings

SEEDS = range(100, 110)


def true_sigma_v(name: str, data: ScenarioData) -> float:
    if name == "skf-sim3":
        return SIM3_NOISE_AMPLITUDE / math.sqrt(3.0)
    noise_free = np.asarray(data.truth["nox_sensor_noise_free_ppm"])
    return float(np.std(data.signals["nox_ppm"] - noise_free))


def spread(values: list[float], fmt: str = "{:.2f}") -> str:
    v = np.asarray(values)
    return f"{fmt.format(np.median(v))} ({fmt.format(v.min())}–{fmt.format(v.max())})"


def sigma_table() -> None:
    print("| scenario | mismatch | filter | seeds | σv true | σ̂v/σv median (min–max) | σ̂w | σ̂f "
          "| evaluations | mean NIS, paper settings | mean NIS, tuned |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    cases = [
        ("skf-sim3", "nominal", "skf", None),
        ("skf-sim3", "nominal", "kf", None),
        ("nox-sdmp", "nominal", "skf", None),
        ("nox-nedc", "nominal", "skf", None),
        ("nox-nedc", "severe", "skf", None),
        ("nox-nedc", "nominal", "kf", 400.0),
    ]
    for name, level, estimator, duration in cases:
        scenario = get_scenario(name)
        ratios, sw, sf, evals, nis0, nis1, truths = [], [], [], [], [], [], []
        for seed in SEEDS:
            data = scenario.build(seed=seed, mismatch=level, duration_s=duration)
            config = scenario.default_config(estimator, data)
            truth = true_sigma_v(name, data)
            paper = stats_of(run_innovations(map_filter(estimator, config), data.signals))
            result = tune(estimator, config, data.signals)
            ratios.append(result.parameters["sigma_v"] / truth)
            sw.append(result.parameters["sigma_w"])
            sf.append(result.parameters.get("sigma_f", math.nan))
            evals.append(result.evaluations)
            nis0.append(paper.mean_nis)
            nis1.append(result.stats.mean_nis)
            truths.append(truth)
        label = name if duration is None else f"{name} (first {duration:g} s)"
        sigma_f = spread(sf, "{:.3g}") if not math.isnan(sf[0]) else "—"
        print(
            f"| {label} | {level} | {estimator} | {SEEDS.start}–{SEEDS.stop - 1} "
            f"| {np.mean(truths):.3g} | {spread(ratios)} | {spread(sw, '{:.3g}')} | {sigma_f} "
            f"| {spread(evals, '{:.0f}')} | {spread(nis0)} | {spread(nis1, '{:.3f}')} |"
        )


def holdout_table() -> None:
    print()
    print("| filter | settings | adapted RMSE [ppm] | base θ0 = 0 | base flat | adapted MAE "
          "| base flat MAE | wins vs flat |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    scenario = get_scenario("nox-nedc")
    rows: dict[tuple[str, str], list[tuple[float, ...]]] = {}
    for seed in SEEDS:
        data = scenario.build(seed=seed)
        y = data.signals["nox_ppm"]
        flat = float(np.mean(y[: round(0.7 * y.size)]))
        skf = scenario.default_config("skf", data)
        tuned = tune("skf", skf, data.signals).parameters
        for estimator in ("kf", "skf"):
            config = scenario.default_config(estimator, data)
            for label, cfg in (("paper (34)", config), ("tuned", with_settings(config, tuned))):
                zero = holdout_error(estimator, cfg, data.signals)
                flat_base = holdout_error(estimator, cfg | {"theta0": flat}, data.signals)
                rows.setdefault((estimator, label), []).append(
                    (
                        zero.adapted["rmse"],
                        zero.base["rmse"],
                        flat_base.base["rmse"],
                        zero.adapted["mae"],
                        flat_base.base["mae"],
                        float(flat_base.adapted["rmse"] < flat_base.base["rmse"]),
                    )
                )
    for (estimator, label), values in rows.items():
        a = np.asarray(values)
        cols = [spread(list(a[:, i]), "{:.1f}") for i in range(5)]
        print(f"| {estimator} | {label} | " + " | ".join(cols) + f" | {int(a[:, 5].sum())}/10 |")


if __name__ == "__main__":
    sigma_table()
    holdout_table()
