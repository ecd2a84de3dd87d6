"""EKF paper §5.2, Table 1: the Def, Aug and Map observers on ``maf-1d-whtc``.

Table 1 lists the mean and maximum estimation errors of the air-path states (intake and
exhaust manifold pressures, turbine speed) and of the compressor flow for the three
observers; ours are computed from the observers' state outputs against the simulator's
truth. The section needs ``ekf-def``, ``ekf-aug`` and ``ekf-map`` in the estimator registry
and says "not available" until they are.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np

from app.cli.run import MISMATCH, ScenarioRun, execute_scenario
from app.reproduce import paper_values as pv
from app.reproduce import seeds as seed_kinds
from app.reproduce.figures import curve_1d, series_panels
from app.reproduce.report import Figure, Section, Table, Text, num
from estimation.metrics import output_metrics
from estimation.registry import registry
from estimation.scenarios import get_scenario

SCENARIO = "maf-1d-whtc"
OBSERVERS = ("ekf-def", "ekf-aug", "ekf-map")
LABELS = {"ekf-def": "Def", "ekf-aug": "Aug", "ekf-map": "Map"}
QUANTITIES = (
    ("p_im_pa", "p_im [Pa]"),
    ("p_em_pa", "p_em [Pa]"),
    ("omega_t_rad_s", "ω_t [rad/s]"),
    ("w_c_kg_s", "W_c [kg/s]"),
)
HISTORY_S = 60.0  # keep the correction map after every minute (EKF Fig. 6)
SIMILAR = 1.5  # "approximately the same": within a factor 1.5
LARGER = 1.5  # "significantly larger": at least 1.5× the larger of Aug and Map


def build(seeds: Sequence[int], *, known: Collection[str] | None = None) -> Section:
    """The section for ``seeds``; ``known`` (default: the estimator registry) are the
    estimator names that can run."""
    section = Section(
        key="ekf",
        title="EKF paper §5.2 — Table 1: Def, Aug and Map observers",
        verdict="",
    )
    known = registry() if known is None else known
    missing = [name for name in OBSERVERS if name not in known]
    if missing:
        section.verdict = (
            f"Not available: {', '.join(missing)} {'is' if len(missing) == 1 else 'are'} not "
            "registered in the estimator registry yet."
        )
        section.blocks.append(Text(f"Paper: {pv.EKF_TABLE1_CLAIM}"))
        return section
    every = max(1, round(HISTORY_S * get_scenario(SCENARIO).rate_hz))
    cases: list[dict[str, ScenarioRun]] = []
    for seed in seeds:
        data = get_scenario(SCENARIO).build(seed=seed, mismatch=MISMATCH.get())
        cases.append(
            {
                name: execute_scenario(SCENARIO, name, seed=seed, data=data, every=every)
                for name in OBSERVERS
            }
        )
    section.blocks.append(
        Text(
            f"Scenario `{SCENARIO}` (air path on the WHTC with W_meas = (1 + q(W))·W, EKF (6)), "
            f"`mismatch = {cases[0]['ekf-def'].data.mismatch}`, observers with their defaults; "
            f"seeds {seed_kinds.describe(seeds)}. Errors are the observers' estimates of the "
            "true states and of the true compressor flow W_c over the whole cycle. Logging: "
            "the sensor averaging of each seed's log (`Scenario.logging`). "
            f"{pv.EKF_TABLE1_NUMBERS_LOST}"
        )
    )
    rows: list[list[str]] = []
    ratios: list[dict[str, tuple[float, float]]] = []
    for runs in cases:
        first = next(iter(runs.values()))
        seed, logging = seed_kinds.label(first.data.seed), first.result["logging"]
        errors = {name: _errors(run) for name, run in runs.items()}
        for key, label in QUANTITIES:
            for stat in ("mae", "max_abs_error"):
                rows.append(
                    [
                        seed,
                        logging,
                        label,
                        "mean |e|" if stat == "mae" else "max |e|",
                        *(num(errors[name][key][stat]) for name in OBSERVERS),
                    ]
                )
        rows.append(
            [
                seed,
                logging,
                "W_c [kg/s]",
                "RMSE (`mapwise run`)",
                *(num(runs[name].result["metrics"]["rmse"]) for name in OBSERVERS),
            ]
        )
        map_rmse = runs["ekf-map"].result["metrics"].get("map_rmse")
        rows.append([seed, logging, "q map", "RMSE on visited cells", "—", "—", num(map_rmse)])
        ratios.append(_ratios(errors))
    section.blocks.append(
        Table(
            "Estimation errors of Def, Aug and Map — our Table 1 (the paper's: Aug ≈ Map, Def "
            "significantly larger).",
            ["Seed", "Logging", "Quantity", "Statistic", "Def", "Aug", "Map"],
            rows,
        )
    )
    section.verdict = _verdict(ratios)
    section.blocks.append(Text(f"Paper: {pv.EKF_TABLE1_CLAIM}"))
    if section.verdict.startswith("Differs"):
        section.blocks.append(
            Text(
                "Where the pattern does not hold: the Aug bias state and the Map parameters run "
                "with their defaults, not the paper's (unpublished) tuning, and the paper notes "
                "that comparing them 'is highly dependent on the filter tuning' (EKF §5.2). "
                f"The maximum W_c errors (seed {seeds[0]}) occur at t = {_peak_times(cases[0])}"
                " s for Def, Aug, Map: the same transient of the cycle, where the air-path "
                "model error is common to all three observers."
            )
        )
    section.blocks += _figures(cases[0])
    return section


def _errors(run: ScenarioRun) -> dict[str, dict[str, float]]:
    truth = run.data.truth["channels"]
    out = {}
    for key, _ in QUANTITIES:
        true = run.data.scored_series[key] if key == "w_c_kg_s" else np.asarray(truth[key])
        estimate = run.final.outputs.get(key)
        out[key] = (
            output_metrics(true - estimate)
            if estimate is not None
            else {"mae": float("nan"), "max_abs_error": float("nan")}
        )
    return out


def _ratios(errors: dict[str, dict[str, dict[str, float]]]) -> dict[str, tuple[float, float]]:
    """Per W_c statistic: (Aug/Map, Def/max(Aug, Map))."""
    out = {}
    for stat in ("mae", "max_abs_error"):
        d, a, m = (errors[name]["w_c_kg_s"][stat] for name in OBSERVERS)
        out[stat] = (a / m, d / max(a, m))
    return out


def _verdict(ratios: Sequence[dict[str, tuple[float, float]]]) -> str:
    """Table 1's pattern on the W_c errors: Aug ≈ Map (within ``SIMILAR``×) and Def larger
    (at least ``LARGER``× the larger of the two), for the mean and the max, per seed."""
    parts, holds = [], True
    for stat, name in (("mae", "mean"), ("max_abs_error", "max")):
        am = [r[stat][0] for r in ratios]
        dl = [r[stat][1] for r in ratios]
        similar = sum(1 / SIMILAR <= v <= SIMILAR for v in am)
        larger = sum(v >= LARGER for v in dl)
        holds &= similar == larger == len(ratios)
        parts.append(
            f"{name} |W_c error|: Aug/Map {_span(am)} (≈ on {similar} of {len(ratios)} seeds), "
            f"Def/max(Aug, Map) {_span(dl)} (larger on {larger} of {len(ratios)})"
        )
    head = "Agrees" if holds else "Differs"
    return (
        f"{head}: Table 1's pattern (Aug ≈ Map within {SIMILAR:g}×, Def ≥ {LARGER:g}× the "
        f"larger) — {'; '.join(parts)}."
    )


def _peak_times(runs: dict[str, ScenarioRun]) -> str:
    times = []
    for name in OBSERVERS:
        run = runs[name]
        error = np.abs(run.data.scored_series["w_c_kg_s"] - run.final.outputs["w_c_kg_s"])
        times.append(f"{run.data.signals.time[int(np.nanargmax(error))]:.0f}")
    return ", ".join(times)


def _span(values: Sequence[float]) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.2f}" if abs(hi - lo) < 0.005 else f"{lo:.2f}–{hi:.2f}"


def _figures(runs: dict[str, ScenarioRun]) -> list[Figure]:
    first = runs["ekf-def"]
    data = first.data
    seed = data.seed
    t = data.signals.time
    w_true = data.scored_series["w_c_kg_s"]
    out = [
        Figure(
            f"{SCENARIO} (seed {seed}): error of the compressor-flow estimate of Def, Aug and "
            "Map — ours for EKF Fig. 4.",
            series_panels(
                f"{SCENARIO}: W_c − Ŵ_c (Fig. 4)",
                t,
                [
                    (
                        "W_c estimation error [kg/s]",
                        {LABELS[n]: w_true - r.final.outputs["w_c_kg_s"] for n, r in runs.items()},
                    )
                ],
                x_title="time [s]",
                height_per_panel=360,
            ),
        )
    ]
    true_map = data.true_map
    table = runs["ekf-map"].final.table
    if true_map is not None and table is not None:
        curves = {
            "true q(W)": (true_map.axes[0].breakpoints, true_map.values),
            "Map: estimated q": (table.axes[0].breakpoints, table.values),
        }
        aug = runs["ekf-aug"].final.outputs
        if "maf_bias_kg_s" in aug and "maf_prediction" in aug:
            b = aug["maf_bias_kg_s"]
            denominator = aug["maf_prediction"] - b
            ok = np.abs(denominator) > 1e-3
            curves["Aug: b/(ŷ − b)"] = (aug["w_c_kg_s"][ok], b[ok] / denominator[ok])
        out.append(
            Figure(
                f"{SCENARIO} (seed {seed}): the true relative MAF error q(W), Map's estimated "
                "correction map and Aug's bias as a relative correction — ours for EKF Fig. 5.",
                curve_1d(f"{SCENARIO}: correction map (Fig. 5)", "W [kg/s]", "q [-]", curves),
            )
        )
        history = runs["ekf-map"].history
        th = np.array([h.time_s for h in history])
        values = np.stack([h.table.values for h in history if h.table is not None])
        grid = table.axes[0].breakpoints
        out.append(
            Figure(
                f"{SCENARIO} (seed {seed}): evolution of Map's correction-map parameters, one "
                "curve per grid point — ours for EKF Fig. 6.",
                series_panels(
                    f"{SCENARIO}: map parameters over time (Fig. 6)",
                    th,
                    [("θ_i [-]", {f"W = {g:.3g}": values[:, i] for i, g in enumerate(grid)})],
                    x_title="time [s]",
                    height_per_panel=380,
                ),
            )
        )
    return out
