"""SKF paper §5 (docs/algorithms.md §2.7): KF, SKF and SSKF on the three synthetic problems.

Scenarios ``skf-sim1..3`` (4×4 table of ones, ``θ0 = 0``, ``P0 = 0``, ``σv² = σw² = 1``).
Each filter runs sample by sample (``every=1``) so the state and variance histories of SKF
Figs. 7–13 can be drawn; the scores are those of ``mapwise run``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.cli.run import MISMATCH, ScenarioRun, execute_scenario
from app.reproduce import paper_values as pv
from app.reproduce.figures import map_heatmaps, series_panels
from app.reproduce.report import Figure, Section, Table, Text, num
from estimation.metrics import cell_visits, convergence_time
from estimation.scenarios import get_scenario

FILTERS = ("kf", "skf", "sskf")
LABELS = {"kf": "KF", "skf": "SKF", "sskf": "SSKF"}
TOLERANCE = 0.15
"""A filter has converged when its final max |error| over the excited cells is at most this:
three quarters of simulation 3's noise amplitude (0.2), far below SSKF's ≈ 0.6 miss."""


@dataclass(frozen=True, slots=True, eq=False)
class SimResult:
    number: int
    seed: int
    runs: dict[str, ScenarioRun]
    visited: np.ndarray  # (p,) cells excited by the inputs (the map_metrics definition)
    k: np.ndarray  # samples consumed after each history snapshot
    max_error: dict[str, np.ndarray]  # filter → max |θ̂ − θ| over visited cells, per k

    def converged(self, estimator: str) -> bool:
        value = self.runs[estimator].result["metrics"]["max_abs_error"]
        return value is not None and value <= TOLERANCE

    def convergence_k(self, estimator: str) -> float | None:
        return convergence_time(self.k, self.max_error[estimator], TOLERANCE)

    def states(self, estimator: str) -> np.ndarray:
        """(k, p) table values after each sample."""
        return np.stack([h.table.values.ravel() for h in self.runs[estimator].history])

    def variances(self, estimator: str) -> np.ndarray:
        return np.stack([h.variance.ravel() for h in self.runs[estimator].history])


def simulate(number: int, seed: int) -> SimResult:
    name = f"skf-sim{number}"
    data = get_scenario(name).build(seed=seed, mismatch=MISMATCH.get())
    assert data.true_map is not None
    truth = data.true_map.values.ravel()
    visited = (cell_visits(data.true_map, data.scoring_points()) >= 1.0).ravel()
    runs = {est: execute_scenario(name, est, seed=seed, data=data, every=1) for est in FILTERS}
    k = np.array([h.sample for h in runs["kf"].history], dtype=np.float64)
    max_error = {
        est: np.array([np.abs(h.table.values.ravel() - truth)[visited].max() for h in r.history])
        for est, r in runs.items()
    }
    return SimResult(number, seed, runs, visited, k, max_error)


def build(seeds: Sequence[int]) -> Section:
    section = Section(
        key="skf",
        title="SKF paper §5 — synthetic checks, simulations 1–3 (KF, SKF, SSKF)",
        verdict="",
    )
    results = [simulate(n, seed) for n in (1, 2, 3) for seed in seeds]
    section.blocks.append(
        Text(
            "Scenarios `skf-sim1`, `skf-sim2`, `skf-sim3` (4×4 table of ones, θ0 = 0, P0 = 0, "
            "σv² = σw² = 1, SKF (20)–(21)); seeds "
            f"{', '.join(map(str, seeds))}. RMSE and max |error| are `mapwise run`'s map "
            "metrics over the excited cells; *converged* means max |error| ≤ "
            f"{TOLERANCE:g} at the end; *k to converge* is the first sample after which the "
            "max |error| over the excited cells stays ≤ that tolerance."
        )
    )
    rows, matches, mismatches = [], 0, []
    for r in results:
        for est in FILTERS:
            m = r.runs[est].result["metrics"]
            expected = pv.SKF_SIM_CONVERGES[r.number][est]
            ours = r.converged(est)
            matches += ours == expected
            if ours != expected:
                mismatches.append(f"sim {r.number} {LABELS[est]} seed {r.seed}")
            k_conv = r.convergence_k(est)
            rows.append(
                [
                    f"{r.number} ({pv.SKF_SIM_REFS[r.number]})",
                    LABELS[est],
                    str(r.seed),
                    "converges" if expected else "does not converge",
                    "converged" if ours else "not converged",
                    num(m["rmse"]),
                    num(m["max_abs_error"]),
                    "—" if k_conv is None else f"{k_conv:.0f}",
                    f"{int(m['visited_cells'])}",
                ]
            )
    section.blocks.append(
        Table(
            "Convergence of KF, SKF and SSKF: the paper's outcome beside ours (SKF §5).",
            [
                "Simulation",
                "Filter",
                "Seed",
                "Paper",
                "Ours",
                "Map RMSE",
                "Max abs error",
                "k to converge",
                "Excited cells",
            ],
            rows,
        )
    )
    section.blocks.append(_variance_table(results))
    total = len(results) * len(FILTERS)
    if mismatches:
        agreement = (
            f"{matches} of {total} outcomes match the paper; differing: "
            f"{'; '.join(mismatches)}. SSKF's fixed gains depend on the data order, so a "
            "different input realisation can let it settle (or not) where the paper's did not."
        )
    else:
        agreement = (
            f"all {total} (simulation, filter, seed) outcomes match the paper: every filter "
            "converges on simulation 1; KF and SKF converge on the 8 excited cells of "
            "simulations 2 and 3 while SSKF does not."
        )
    section.verdict = agreement[0].upper() + agreement[1:]
    for number in (1, 2, 3):
        section.blocks.append(Text(f"**Simulation {number}.** Paper: {pv.SKF_SIM_CLAIMS[number]}"))
    section.blocks += _figures(results[:: len(seeds)])
    return section


def _variance_table(results: Sequence[SimResult]) -> Table:
    rows = []
    for r in results:
        kf, skf = r.variances("kf"), r.variances("skf")
        diff = np.where(r.visited, np.abs(kf - skf), 0.0)
        end = int(np.argmax(diff[-1]))
        rows.append(
            [
                str(r.number),
                str(r.seed),
                num(float(diff.max())),
                num(float(diff[-1, end])),
                f"x{end + 1}: {num(float(kf[-1, end]))} / {num(float(skf[-1, end]))}",
            ]
        )
    return Table(
        "KF against SKF variances on the excited cells (SKF Fig. 8: an offset that is later "
        "absorbed; Fig. 10: 'similar, although some deviation exists in elements 6 and 7'). "
        "Elements x_i are 1-based, row-major as in the paper.",
        [
            "Simulation",
            "Seed",
            "max over k of |P_KF − P_SKF|",
            "largest at the end",
            "where: P_KF / P_SKF",
        ],
        rows,
    )


def _figures(first_seed: Sequence[SimResult]) -> list[Figure]:
    sim1, sim2, sim3 = first_seed
    seed = sim1.seed
    out: list[Figure] = []
    i6 = pv.SKF_SIM1_ELEMENT - 1
    states1 = {LABELS[e]: sim1.states(e) for e in FILTERS}
    out.append(
        Figure(
            f"Simulation 1 (seed {seed}): mean of all 16 states and x6 with its variance P6 — "
            "ours for SKF Figs. 7 and 8.",
            series_panels(
                "skf-sim1: mean of all states (Fig. 7), x6 (Fig. 8 bottom), P6 (Fig. 8 top)",
                sim1.k,
                [
                    ("mean of all states", {n: s.mean(axis=1) for n, s in states1.items()}),
                    ("x6", {n: s[:, i6] for n, s in states1.items()}),
                    (
                        "P6",
                        {LABELS[e]: sim1.variances(e)[:, i6] for e in ("kf", "skf")},
                    ),
                ],
                x_title="k",
                dash={"SKF": "dash"},
            ),
        )
    )
    for sim, fig_ref in ((sim2, "Fig. 9"), (sim3, "Fig. 13")):
        states = {LABELS[e]: sim.states(e) for e in FILTERS}
        panels: list[tuple[str, dict[str, np.ndarray]]] = []
        if sim.number == 3:
            y = sim.runs["kf"].data.signals["y"]
            panels.append(("measurement y_k (Fig. 12)", {"y": y}))
        panels += [
            (f"x{i}", {n: s[:, i - 1] for n, s in states.items()}) for i in pv.SKF_SIM2_ELEMENTS
        ]
        out.append(
            Figure(
                f"Simulation {sim.number} (seed {seed}): states x5…x8 — ours for SKF {fig_ref}.",
                series_panels(
                    f"skf-sim{sim.number}: x5…x8 ({fig_ref})",
                    sim.k,
                    panels,
                    x_title="k",
                    dash={"SKF": "dash"},
                ),
            )
        )
    out.append(
        Figure(
            f"Simulation 2 (seed {seed}): variances P5…P8, KF (solid) and SKF (dashed) — ours "
            "for SKF Fig. 10.",
            series_panels(
                "skf-sim2: variances of x5…x8 (Fig. 10)",
                sim2.k,
                [
                    (f"P{i}", {LABELS[e]: sim2.variances(e)[:, i - 1] for e in ("kf", "skf")})
                    for i in pv.SKF_SIM2_ELEMENTS
                ],
                x_title="k",
                dash={"SKF": "dash"},
            ),
        )
    )
    true_map = sim2.runs["kf"].data.true_map
    assert true_map is not None
    mask = np.where(sim2.visited.reshape(true_map.shape), 1.0, np.nan)
    panels_map = [("true", true_map.values)] + [
        (LABELS[e], sim2.runs[e].final.table.values) for e in FILTERS
    ]
    sskf_error = (sim2.runs["sskf"].final.table.values - true_map.values) * mask
    panels_map.append(("SSKF error (excited cells)", sskf_error))
    out.append(
        Figure(
            f"Simulation 2 (seed {seed}): the true table, the final estimates and SSKF's error "
            "on the excited cells (rows u1 = 1500, 2500 rpm).",
            map_heatmaps(
                "skf-sim2: final maps",
                true_map,
                panels_map,
                unit="-",
                diverging=[False] * 4 + [True],
                points=sim2.runs["kf"].data.scoring_points(),
            ),
        )
    )
    return out
