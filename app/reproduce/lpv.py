"""LPV paper §4: the MAF-sensor error map ``ΔW_c(u_δ, n_e)`` learnt by the LPV adaptive
observer on ``maf-whtc`` (standing in for ETC part 1) and ``maf-ftp75``.

The mean relative error is ``mapwise run``'s (docs/algorithms.md §3: the final map against the
reference error along the cycle's operating points), set beside the paper's 10.41 % and
5.28 % for every seed. Maps: the true one, ours on the visited cells, the error, and the
LPV (37) quadratic fill of the unvisited region (LPV Figs. 5, 8); along the cycle: the
reference error against the estimate and the corrected MAF signal (LPV Figs. 6, 9).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np

from app.cli.run import ScenarioRun, execute_scenario
from app.reproduce import paper_values as pv
from app.reproduce.figures import map_heatmaps, map_surfaces, series_panels
from app.reproduce.report import Figure, Section, Table, Text, num, pct
from estimation.errors import EstimationError
from estimation.metrics import cell_visits
from estimation.registry import registry

SCENARIOS = ("maf-whtc", "maf-ftp75")
ESTIMATOR = "lpv"


def build(seeds: Sequence[int], *, known: Collection[str] | None = None) -> Section:
    """The section for ``seeds``; ``known`` (default: the estimator registry) are the
    estimator names that can run."""
    section = Section(
        key="lpv",
        title="LPV paper §4 — MAF-sensor error map, mean relative errors and maps (Figs. 5–9)",
        verdict="",
    )
    if ESTIMATOR not in (registry() if known is None else known):
        section.verdict = f"Not available: the estimator {ESTIMATOR!r} is not registered."
        return section
    runs = {
        (s, seed): execute_scenario(s, ESTIMATOR, seed=seed) for s in SCENARIOS for seed in seeds
    }
    section.blocks.append(
        Text(
            "Scenarios `maf-whtc` (the WHTC stands in for the paper's ETC part 1) and "
            f"`maf-ftp75`, grid {pv.LPV_GRID}, estimator `lpv` with its defaults (ε1 = 0.25, "
            "ε2 = 0.11 as LPV §4; a visit-averaging adaptation gain starting at γ = 10 instead "
            "of the paper's constant γ = 200, and ρ1 from the intake-manifold balance — see the "
            f"`lpv` docstring); seeds {', '.join(map(str, seeds))}. The mean "
            "relative error is docs/algorithms.md §3's: Σ_k |T̂(υ_k) − ΔW_c(υ_k)| / Σ_k |ΔW_c(υ_k)| "
            "with the final map T̂ along the cycle (the paper does not define its own). Map "
            "RMSE and max |error| are over the visited cells, in kg/s."
        )
    )
    rows, within = [], 0
    for (scenario, seed), run in runs.items():
        m = run.result["metrics"]
        paper = pv.LPV_MEAN_RELATIVE_ERROR[scenario]
        ours = m["mean_relative_error"]
        ok = ours is not None and ours <= paper
        within += ok
        rows.append(
            [
                f"{scenario} ({pv.LPV_REFS[scenario]})",
                str(seed),
                pct(paper),
                pct(ours),
                "yes" if ok else "no",
                num(m.get("map_rmse")),
                num(m["max_abs_error"]),
                num(m.get("rmse")),
                f"{m['coverage']:.0%} ({int(m['visited_cells'])} cells)",
            ]
        )
    section.blocks.append(
        Table(
            "Mean relative error of the estimated MAF-error map: the paper's beside ours.",
            [
                "Scenario",
                "Seed",
                "Paper MRE",
                "Our MRE",
                "Within the paper's",
                "Map RMSE [kg/s]",
                "Max abs error [kg/s]",
                "W_c RMSE [kg/s]",
                "Coverage",
            ],
            rows,
        )
    )
    total = len(runs)
    if within == total:
        section.verdict = (
            f"Agrees: the mean relative error is within the paper's figure on all {total} "
            "(scenario, seed) runs."
        )
    else:
        worst = max(
            runs.items(),
            key=lambda kv: (
                (kv[1].result["metrics"]["mean_relative_error"] or np.inf)
                / pv.LPV_MEAN_RELATIVE_ERROR[kv[0][0]]
            ),
        )
        section.verdict = (
            f"Differs: {within} of {total} runs are within the paper's mean relative error; "
            f"the worst is {worst[0][0]} seed {worst[0][1]} at "
            f"{pct(worst[1].result['metrics']['mean_relative_error'])} against "
            f"{pct(pv.LPV_MEAN_RELATIVE_ERROR[worst[0][0]])}."
        )
        section.blocks.append(
            Text(
                "Where ours is larger: our air path is a reconstruction of the paper's enDYNA "
                "1.9 L engine (commercial, not available), driven by the WHTC instead of ETC "
                "part 1, with our own MAF error map and measurement noise; the paper reports "
                "one run and does not define its mean relative error, so it may be taken over "
                "the visited cells or only after convergence."
            )
        )
    for scenario in SCENARIOS:
        section.blocks += _figures(scenario, runs[(scenario, seeds[0])])
    return section


def _figures(scenario: str, run: ScenarioRun) -> list[Figure]:
    data, final = run.data, run.final
    true_map, table = data.true_map, final.table
    assert true_map is not None
    assert table is not None
    seed = data.seed
    points = data.scoring_points()
    visited = cell_visits(true_map, points) >= 1.0
    estimated = np.where(visited, table.values, np.nan)
    panels = [
        ("true ΔW_c", true_map.values),
        ("estimated (visited cells)", estimated),
        ("error (visited cells)", estimated - true_map.values),
    ]
    flags = [False, False, True]
    note = ""
    try:
        from estimation.observers.lpv_fill import fill_quadratic

        filled, _ = fill_quadratic(table, visited)
        panels.append(("with the LPV (37) fill", filled.values))
        flags.append(False)
    except (ImportError, EstimationError) as exc:
        note = f" (LPV (37) fill unavailable: {exc})"
    out = [
        Figure(
            f"{scenario} (seed {seed}): the reference MAF error map, ours on the visited "
            "cells, the error, and the unvisited region filled by LPV (37) — ours for LPV "
            f"Figs. 3 and {'5' if scenario == 'maf-whtc' else '8'}{note}. Colours span the "
            "true map's range; estimates beyond it saturate.",
            map_heatmaps(
                f"{scenario}: MAF error maps [kg/s]",
                true_map,
                panels,
                unit="kg/s",
                diverging=flags,
                points=points,
            ),
        ),
        Figure(
            f"{scenario} (seed {seed}): the true map and ours (visited cells) as surfaces.",
            map_surfaces(
                f"{scenario}: true (Viridis) and estimated (Reds) ΔW_c",
                true_map,
                [("true", true_map.values), ("estimated", estimated)],
                unit="kg/s",
            ),
        ),
    ]
    t = data.signals.time
    reference = true_map.evaluate(points)
    along = {"reference ΔW_c(υ_k)": reference, "final map T̂(υ_k)": table.evaluate(points)}
    online = final.outputs.get("maf_error_kg_s")
    if online is not None:
        along["online estimate ψᵀθ̂"] = online
    flows = {
        "true W_c": data.scored_series["w_c_kg_s"],
        "measured (MAF)": data.signals["maf_kg_s"],
        "corrected: MAF − T̂(υ_k)": data.signals["maf_kg_s"] - table.evaluate(points),
    }
    fig_ref = "Fig. 6" if scenario == "maf-whtc" else "Fig. 9"
    out.append(
        Figure(
            f"{scenario} (seed {seed}): the reference error against the estimate along the "
            f"cycle, and the MAF signal before and after correction — ours for LPV {fig_ref}.",
            series_panels(
                f"{scenario}: map compensation along the cycle ({fig_ref})",
                t,
                [("MAF error [kg/s] (a)", along), ("air mass flow [kg/s] (b)", flows)],
                x_title="time [s]",
                height_per_panel=300,
            ),
        )
    )
    return out
