"""LPV paper §4: the MAF-sensor error map ``ΔW_c(u_δ, n_e)`` learnt by the LPV adaptive
observer on ``maf-whtc`` (standing in for ETC part 1) and ``maf-ftp75``.

The mean relative error is ``mapwise run``'s (docs/algorithms.md §3: the final map against the
reference error along the cycle's operating points). The paper's figures are about its own
segments, ETC part 1 (10.41 %) and the FTP-75 cold start (5.28 %), so each (scenario, seed)
has two rows: the observer run over the paper's segment (WHTC 0–600 s, FTP-75 0–505 s:
:data:`app.reproduce.fidelity.SEGMENTS_S`), whose MRE is set against the paper's figure and
makes the verdict, and the whole cycle, reported beside it. Each row names the sensor logging
of its log (``Scenario.logging``, docs/fidelity.md#mismatch). Maps: the true one, ours on the
visited cells, the error, and the LPV (37) quadratic fill of the unvisited region (LPV Figs.
5, 8); along the cycle: the reference error against the estimate and the corrected MAF signal
(LPV Figs. 6, 9).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np

from app.cli.run import ScenarioRun, execute_scenario
from app.reproduce import paper_values as pv
from app.reproduce import seeds as seed_kinds
from app.reproduce.fidelity import SEGMENTS_S, head
from app.reproduce.figures import map_heatmaps, map_surfaces, series_panels
from app.reproduce.report import Figure, Section, Table, Text, num, pct
from estimation.errors import EstimationError
from estimation.metrics import cell_visits
from estimation.observers.lpv_config import LpvConfig
from estimation.registry import registry

SCENARIOS = ("maf-whtc", "maf-ftp75")
ESTIMATOR = "lpv"
SPANS = ("segment", "full")
"""Per (scenario, seed): the paper's segment (the verdict's figure), then the whole cycle."""
SEGMENT_NAMES = {"maf-whtc": "ETC part 1 stand-in", "maf-ftp75": "cold start"}


def _span_label(scenario: str, span: str, run: ScenarioRun) -> str:
    if span == "segment":
        return f"0–{SEGMENTS_S[scenario]:g} s ({SEGMENT_NAMES[scenario]}, the paper's span)"
    t = run.data.signals.time
    return f"whole cycle (0–{t[-1] - t[0]:.0f} s)"


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
    runs: dict[tuple[str, int], dict[str, ScenarioRun]] = {}
    for scenario in SCENARIOS:
        for seed in seeds:
            full = execute_scenario(scenario, ESTIMATOR, seed=seed)
            segment = head(full.data, SEGMENTS_S[scenario])
            runs[(scenario, seed)] = {
                "segment": execute_scenario(scenario, ESTIMATOR, seed=seed, data=segment),
                "full": full,
            }
    first = runs[(SCENARIOS[0], seeds[0])]["full"]
    section.blocks.append(
        Text(
            "Scenarios `maf-whtc` (the WHTC stands in for the paper's ETC part 1) and "
            f"`maf-ftp75`, grid {pv.LPV_GRID}, `mismatch = {first.data.mismatch}`, estimator "
            "`lpv` with its defaults (ε1 = 0.25, ε2 = 0.11 as LPV §4; a visit-averaging "
            f"adaptation gain starting at γ = {LpvConfig().gamma:g}, chosen by the declared "
            "rule on tuning seeds 0–4 (section `sensitivity`), instead of the paper's constant "
            "Γ = 200 I; ρ from the observer's own identified model — see the `lpv` docstring); "
            f"seeds {seed_kinds.describe(seeds)}. The paper's figures are over its segments, "
            "so the observer is run over the same spans (WHTC 0–600 s for ETC part 1, FTP-75 "
            "0–505 s cold start) and those rows are compared with them; the whole-cycle rows "
            "are reported beside. The mean relative error is docs/algorithms.md §3's: "
            "Σ_k |T̂(υ_k) − ΔW_c(υ_k)| / Σ_k |ΔW_c(υ_k)| with the final map T̂ along the run "
            "(the paper does not define its own). Map RMSE and max |error| are over the "
            "visited cells, in kg/s. Logging: the sensor averaging of each row's log "
            "(`Scenario.logging`)."
        )
    )
    rows, records = [], []
    for (scenario, seed), pair in runs.items():
        paper = pv.LPV_MEAN_RELATIVE_ERROR[scenario]
        for span in SPANS:
            run = pair[span]
            m = run.result["metrics"]
            ours = m["mean_relative_error"]
            within = ours is not None and ours <= paper
            rows.append(
                [
                    f"{scenario} ({pv.LPV_REFS[scenario]})",
                    _span_label(scenario, span, run),
                    seed_kinds.label(seed),
                    run.result["logging"],
                    pct(paper),
                    pct(ours),
                    ("yes" if within else "no") if span == "segment" else "— (not its span)",
                    num(m.get("map_rmse")),
                    num(m["max_abs_error"]),
                    num(m.get("rmse")),
                    f"{m['coverage']:.0%} ({int(m['visited_cells'])} cells)",
                ]
            )
            records.append(
                {
                    "scenario": scenario,
                    "span": span,
                    "seconds": float(run.data.signals.time[-1] - run.data.signals.time[0]),
                    "seed": seed,
                    "seed_kind": seed_kinds.kind(seed),
                    "logging": run.result["logging"],
                    "paper_mre": paper,
                    "mre": ours,
                    "within": within if span == "segment" else None,
                }
            )
    section.blocks.append(
        Table(
            "Mean relative error of the estimated MAF-error map: the paper's beside ours, over "
            "the paper's segment (compared) and the whole cycle (reported).",
            [
                "Scenario",
                "Span",
                "Seed",
                "Logging",
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
    section.data = {"rows": records}
    section.verdict = _verdict(records)
    if not section.verdict.startswith("Agrees"):
        section.blocks.append(
            Text(
                "Where ours is larger: our air path is a reconstruction of the paper's enDYNA "
                "1.9 L engine (commercial, not available), driven by the WHTC instead of ETC "
                "part 1, with our own MAF error map and measurement noise; under mismatch the "
                "observer measures the MAF against its own identified flow model, whose "
                "residual error is a large fraction of the small FTP-75 map "
                "(docs/fidelity.md#held-out). The paper reports one run and does not define "
                "its mean relative error, so it may be taken over the visited cells or only "
                "after convergence."
            )
        )
    for scenario in SCENARIOS:
        section.blocks += _figures(scenario, runs[(scenario, seeds[0])]["full"])
    return section


def _verdict(records: Sequence[dict[str, object]]) -> str:
    """Against the papers' figures over their segments, per scenario; the whole-cycle seed
    means beside."""
    segments = [r for r in records if r["span"] == "segment"]
    within = sum(bool(r["within"]) for r in segments)
    per = []
    for scenario in SCENARIOS:
        mine = [r for r in segments if r["scenario"] == scenario]
        full = [r["mre"] for r in records if r["scenario"] == scenario and r["span"] == "full"]
        finite = [float(v) for v in full if v is not None]  # type: ignore[arg-type]
        whole = pct(float(np.mean(finite))) if finite else "n/a"
        per.append(
            f"{scenario} 0–{SEGMENTS_S[scenario]:g} s: {sum(bool(r['within']) for r in mine)} "
            f"of {len(mine)} within {pct(pv.LPV_MEAN_RELATIVE_ERROR[scenario])} "
            f"(whole cycle: seed mean {whole})"
        )
    if within == len(segments):
        return (
            "Agrees: over the papers' segments the mean relative error is within the paper's "
            f"figure on all {len(segments)} (scenario, seed) runs — {'; '.join(per)}."
        )
    worst = max(
        segments,
        key=lambda r: (
            (np.inf if r["mre"] is None else float(r["mre"]))  # type: ignore[arg-type]
            / float(r["paper_mre"])
        ),  # type: ignore[arg-type]
    )
    return (
        f"Differs: {within} of {len(segments)} runs are within the paper's mean relative "
        f"error over its segment — {'; '.join(per)}; the worst is {worst['scenario']} seed "
        f"{worst['seed']} at {pct(worst['mre'])} against {pct(worst['paper_mre'])}."  # type: ignore[arg-type]
    )


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
