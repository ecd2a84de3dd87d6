"""SKF paper §6: the NOx map behind a delayed, lagged sensor (scenarios ``nox-sdmp``,
``nox-nedc``) learnt by KF, SKF, SSKF and the RLS / NLMS baselines.

Besides ``mapwise run``'s scores, the map after every second of learning is kept, to draw
SKF (35)'s convergence curve: ``e_M(t) = mean_k |y_NOx(k) − y_M(k)|_t|`` [ppm], the mean
absolute error over the whole cycle of the sensor signal predicted by the dynamic model
(SKF (23)–(25): delay τ, lag a) with the table learnt until ``t``. The *benchmark* is the same
model with the true map of the start of the record, which does not follow the drift.
SKF Fig. 17's online fit is read from the filter's own innovation (``residual`` output).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.cli.run import MISMATCH, ScenarioRun, execute_scenario
from app.reproduce import paper_values as pv
from app.reproduce.figures import map_heatmaps, series_panels
from app.reproduce.nox_sensor import SensorModel
from app.reproduce.report import Figure, Section, Table, Text, num, pct
from estimation.metrics import cell_visits
from estimation.scenarios import ScenarioData, get_scenario
from estimation.table import Table as MapTable

SCENARIOS = ("nox-sdmp", "nox-nedc")
CAL36 = {"sigma_w": pv.NOX_CAL36_SIGMA_W}
VARIANTS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("KF", "kf", {}),
    ("SKF", "skf", {}),
    ("SSKF", "sskf", {}),
    ("RLS", "rls", {}),
    ("NLMS", "nlms", {}),
    ("KF Cal (36)", "kf", CAL36),
    ("SKF Cal (36)", "skf", CAL36),
)
"""Label, estimator, overrides of the scenario's SKF (34) configuration."""
HISTORY_S = 1.0  # keep the map after every second of learning
E_M_EVERY_S = 10.0  # evaluate e_M(t) every 10 s
PREDICTS_WELL = 1.5  # Fig. 14 "predicts well": e_M(400 s) at most 1.5× the benchmark's
FIT_WINDOW_S = 10.0  # Fig. 17: moving RMS window of the online innovation
FITS = 1.5  # Fig. 17 "fits": that moving RMS at most 1.5× the sensor noise RMS
ALIKE = 0.05  # Fig. 16 "pretty similar": KF and SKF variances within 5 % of each other


@dataclass(frozen=True, slots=True, eq=False)
class NoxRun:
    label: str
    run: ScenarioRun
    t: np.ndarray  # times the map was sampled [s]
    e_m: np.ndarray  # SKF (35) at those times [ppm]

    def e_m_at(self, t_s: float) -> float:
        return float(np.interp(t_s, self.t, self.e_m))

    def fit_time_s(self, noise_rms: float, rate_hz: float) -> float | None:
        """Fig. 17: end of the first ``FIT_WINDOW_S`` window whose innovation RMS is at
        most ``FITS`` × the sensor noise RMS (accepted samples only)."""
        status = self.run.final.status
        residual = self.run.final.outputs["residual"]
        e2 = np.where(status == 0, residual, 0.0) ** 2
        n = max(1, round(FIT_WINDOW_S * rate_hz))
        used = np.convolve((status == 0).astype(float), np.ones(n), "valid")
        rms = np.sqrt(np.convolve(e2, np.ones(n), "valid") / np.maximum(used, 1.0))
        hits = np.nonzero((used >= n / 2) & (rms <= FITS * noise_rms))[0]
        return None if hits.size == 0 else float(hits[0] + n) / rate_hz


@dataclass(frozen=True, slots=True, eq=False)
class NoxCase:
    scenario: str
    seed: int
    data: ScenarioData
    runs: dict[str, NoxRun]
    benchmark_e_m: float
    benchmark_map_error: float  # mean |T_initial(u_k) − NOx_true(k)| [ppm]
    prediction: dict[str, np.ndarray]  # label → y_M over the cycle with the map at 400 s
    unlearnt_share: float  # share of the cycle in cells not yet visited at 400 s
    mre_400: dict[str, float]  # label → mean relative error along the cycle of the 400 s map

    @property
    def noise_rms(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.data.truth["noise_ppm"]))))


def run_case(scenario: str, seed: int) -> NoxCase:
    data = get_scenario(scenario).build(seed=seed, mismatch=MISMATCH.get())
    model = SensorModel(data)
    every = max(1, round(HISTORY_S * get_scenario(scenario).rate_hz))
    pick = max(1, round(E_M_EVERY_S / HISTORY_S))
    t_400 = data.signals.time[0] + pv.NOX_UPDATE_WINDOW_S
    runs: dict[str, NoxRun] = {}
    prediction: dict[str, np.ndarray] = {}
    mre_400: dict[str, float] = {}
    assert data.true_map is not None
    true_along = model.psi @ data.true_map.flat
    for label, estimator, overrides in VARIANTS:
        run = execute_scenario(
            scenario, estimator, seed=seed, data=data, overrides=overrides, every=every
        )
        picked = run.history[::pick]
        t = np.array([h.time_s - data.signals.time[0] for h in picked])
        runs[label] = NoxRun(label, run, t, model.e_m([h.table for h in picked]))
        map_400 = _map_at(run, t_400)
        prediction[label] = model.predict(map_400)
        along = model.psi @ map_400.flat
        mre_400[label] = float(np.sum(np.abs(along - true_along)) / np.sum(np.abs(true_along)))
    initial = MapTable.from_dict(data.truth["initial_map"])
    prediction["benchmark"] = model.predict(initial)
    points = data.scoring_points()
    true_nox = np.asarray(data.truth["nox_true_ppm"])
    early = data.signals.time <= t_400
    learnt = (cell_visits(initial, points[early]) >= 1.0).ravel()
    idx, w = initial.regressor(points)
    dominant = idx[np.arange(len(idx)), np.argmax(w, axis=1)]
    return NoxCase(
        scenario=scenario,
        seed=seed,
        data=data,
        runs=runs,
        benchmark_e_m=float(model.e_m([initial])[0]),
        benchmark_map_error=float(np.mean(np.abs(initial.evaluate(points) - true_nox))),
        prediction=prediction,
        unlearnt_share=float(np.mean(~learnt[dominant])),
        mre_400=mre_400,
    )


def _map_at(run: ScenarioRun, time_s: float) -> MapTable:
    times = np.array([h.time_s for h in run.history])
    i = min(int(np.searchsorted(times, time_s)), len(times) - 1)
    table = run.history[i].table
    assert table is not None
    return table


def build(seeds: Sequence[int]) -> Section:
    section = Section(
        key="nox",
        title="SKF paper §6 — NOx map learning (Figs. 14–18)",
        verdict="",
    )
    cases = [run_case(s, seed) for s in SCENARIOS for seed in seeds]
    section.blocks.append(
        Text(
            "Scenarios `nox-sdmp` and `nox-nedc` (12×18 table, SKF (34): σv = 25, σw = 15, "
            "σf = 50 ppm, a = 0.96, τ = 0.75 s at 50 Hz, T_NOx,0 = 0; Cal (36): σw = 7 for KF "
            f"and SKF); seeds {', '.join(map(str, seeds))}. Map RMSE / max |error| over the "
            "visited cells and the mean relative error along the cycle are `mapwise run`'s "
            "metrics against the true (drifted, end-of-record) map; output RMSE is the RMS "
            "of the filter's online innovation. e_M is SKF (35): the mean absolute error of "
            "the NOx sensor predicted over the whole cycle by the dynamic model with the map "
            "learnt until t; *mean e_M(t)* averages it over t (the area under our Fig. 15). "
            "*Benchmark* is the same model with the true map of the start of the record (a "
            "fixed calibration that does not follow the drift)."
        )
    )
    rows = []
    for c in cases:
        for label, r in c.runs.items():
            m = r.run.result["metrics"]
            rows.append(
                [
                    c.scenario,
                    str(c.seed),
                    label,
                    num(m["rmse"]),
                    num(m["max_abs_error"]),
                    pct(m["mean_relative_error"], 1),
                    num(m["output_rmse"]),
                    num(r.e_m_at(pv.NOX_UPDATE_WINDOW_S), 3),
                    num(float(r.e_m[-1]), 3),
                    num(float(np.mean(r.e_m)), 3),
                    num(c.benchmark_e_m, 3),
                ]
            )
    section.blocks.append(
        Table(
            "Map and prediction errors of every filter (SKF Figs. 14, 15, 18); ppm unless stated.",
            [
                "Scenario",
                "Seed",
                "Filter",
                "Map RMSE",
                "Max abs error",
                "Mean rel. error",
                "Output RMSE",
                "e_M(400 s)",
                "e_M(end)",
                "mean e_M(t)",
                "Benchmark e_M",
            ],
            rows,
        )
    )
    section.blocks.append(_variance_table(cases))
    findings = _findings(cases)
    section.blocks.append(
        Text("\n".join(f"- {claim} **Ours:** {finding}" for claim, finding in findings))
    )
    agree = sum(1 for _, f in findings if f.startswith("agrees"))
    section.verdict = (
        f"{agree} of {len(findings)} of the paper's NOx claims hold on every seed (details "
        "below). The paper's figures are curves against a real engine's sensor, so its claims "
        "are compared, not values."
    )
    section.blocks += _figures([c for c in cases if c.seed == seeds[0]])
    return section


def _variance_table(cases: Sequence[NoxCase]) -> Table:
    rows = []
    for c in cases:
        for element in pv.NOX_FIG16_ELEMENTS:
            kf, skf = _variances(c, element)
            rows.append(
                [
                    c.scenario,
                    str(c.seed),
                    str(element),
                    num(float(np.max(kf))),
                    num(float(np.max(np.abs(kf - skf)))),
                    pct(_relative(kf, skf), 2),
                    pct(float(abs(kf[-1] - skf[-1]) / max(kf[-1], 1e-12)), 2),
                ]
            )
    return Table(
        "Variances of table elements 126 and 133 (1-based), KF against SKF with Cal (36) — "
        "SKF Fig. 16 ('differences can be found only when zooming in').",
        [
            "Scenario",
            "Seed",
            "Element",
            "max P_KF [ppm²]",
            "max |P_KF − P_SKF|",
            "max relative",
            "relative at the end",
        ],
        rows,
    )


def _variances(case: NoxCase, element: int) -> tuple[np.ndarray, np.ndarray]:
    """Variance of a (1-based) element after every second, KF and SKF with Cal (36)."""
    return tuple(  # type: ignore[return-value]
        np.array([h.variance.ravel()[element - 1] for h in case.runs[label].run.history])
        for label in ("KF Cal (36)", "SKF Cal (36)")
    )


def _relative(kf: np.ndarray, skf: np.ndarray) -> float:
    return float(np.max(np.abs(kf - skf) / np.maximum(kf, 1e-12)))


def _findings(cases: Sequence[NoxCase]) -> list[tuple[str, str]]:
    sdmp = [c for c in cases if c.scenario == "nox-sdmp"]
    nedc = [c for c in cases if c.scenario == "nox-nedc"]
    out: list[tuple[str, str]] = []

    worst = {
        lab: max(c.runs[lab].e_m_at(pv.NOX_UPDATE_WINDOW_S) / c.benchmark_e_m for c in sdmp)
        for lab in ("KF", "SKF", "SSKF")
    }
    ok = all(v <= PREDICTS_WELL for v in worst.values())
    shares = ", ".join(f"{c.unlearnt_share:.1%}" for c in sdmp)
    mre = ", ".join(
        f"{lab} " + "/".join(f"{c.mre_400[lab]:.0%}" for c in sdmp) for lab in ("KF", "SKF", "SSKF")
    )
    out.append(
        (
            pv.NOX_CLAIMS["fig14"],
            f"{'agrees' if ok else 'differs'}: e_M with the 400 s maps is at most "
            + ", ".join(f"{lab} {v:.2f}×" for lab, v in worst.items())
            + f" the benchmark's over the seeds (we call ≤ {PREDICTS_WELL:g}× 'predicts well')"
            + (
                "."
                if ok
                else f"; only {shares} of the cycle's samples sit in cells not yet visited at "
                "400 s, so the excess is map error on visited cells: the 400 s maps' mean "
                f"relative error along the cycle is {mre} (seeds in order) — through a 0.96 "
                "lag and 0.75 s delay each sample informs a blur of recently visited cells."
            ),
        )
    )

    area = {lab: [float(np.mean(c.runs[lab].e_m)) for c in sdmp] for lab in ("KF", "SKF", "SSKF")}
    faster = [max(area["KF"][i], area["SKF"][i]) < area["SSKF"][i] for i in range(len(sdmp))]
    ratio = [
        c.runs["SKF"].run.result["metrics"]["rmse"] / c.runs["KF"].run.result["metrics"]["rmse"]
        for c in sdmp
    ]
    cal = [np.mean(c.runs["SKF Cal (36)"].e_m) < np.mean(c.runs["SKF"].e_m) for c in sdmp]
    ok = all(faster) and all(0.8 <= r <= 1.25 for r in ratio)
    out.append(
        (
            pv.NOX_CLAIMS["fig15"],
            f"{'agrees' if ok else 'differs'}: SKF/KF final map RMSE ratio "
            + ", ".join(f"{r:.3f}" for r in ratio)
            + f" (alike: within 0.8–1.25); mean e_M(t) of KF and SKF below SSKF's on "
            f"{sum(faster)} of {len(sdmp)} seeds; SKF's mean e_M(t) is lower with Cal (36) "
            f"than with Cal (34) on {sum(cal)} of {len(sdmp)} seeds.",
        )
    )

    rel = {
        (c.scenario, c.seed, e): _relative(*_variances(c, e))
        for c in cases
        for e in pv.NOX_FIG16_ELEMENTS
    }
    worst_key = max(rel, key=rel.__getitem__)
    ok = rel[worst_key] <= ALIKE
    out.append(
        (
            pv.NOX_CLAIMS["fig16"],
            f"{'agrees' if ok else 'differs'}: the largest relative KF–SKF difference of the "
            f"two variances over time is {rel[worst_key]:.1%} (element {worst_key[2]}, "
            f"{worst_key[0]} seed {worst_key[1]}; we call ≤ {ALIKE:.0%} 'pretty similar')"
            + (
                "."
                if ok
                else "; SKF forgets the covariance of elements that stop being jointly active "
                "(SKF §5.2), so an element's variance drops less when it is re-learnt through "
                "its neighbours; the gap closes while the element stays active (see the end "
                "column)."
            ),
        )
    )

    fits = [c.runs["SKF Cal (36)"].fit_time_s(c.noise_rms, 50.0) for c in sdmp]
    ok = all(f is not None and f <= pv.NOX_FIT_TIME_S for f in fits)
    out.append(
        (
            pv.NOX_CLAIMS["fig17"],
            f"{'agrees' if ok else 'differs'}: on nox-sdmp the {FIT_WINDOW_S:g} s moving RMS "
            f"of SKF Cal (36)'s online innovation is first within {FITS:g}× the sensor noise "
            "RMS after "
            + ", ".join("never" if f is None else f"{f:.0f} s" for f in fits)
            + (
                " (the sensor state y_M with σf = 50 ppm takes up the error at once)."
                if ok
                else "."
            ),
        )
    )

    better = [float(c.runs["SKF Cal (36)"].e_m[-1] / c.benchmark_e_m) for c in nedc]
    ok = all(b <= 1.0 for b in better)
    bench = ", ".join(f"{c.benchmark_map_error:.1f}" for c in nedc)
    out.append(
        (
            pv.NOX_CLAIMS["fig18"],
            f"{'agrees' if ok else 'differs'}: on nox-nedc the e_M of the SKF Cal (36) map "
            "after one cycle is "
            + ", ".join(f"{b:.3f}×" for b in better)
            + " the benchmark's"
            + (
                "."
                if ok
                else f"; our benchmark is the true map of the record's start, off the true NOx "
                f"by only {bench} ppm on average (the simulated drift over one cycle), while "
                "the paper's benchmark was a physical model with its own error and drift."
            ),
        )
    )
    return out


def _figures(cases: Sequence[NoxCase]) -> list[Figure]:
    out: list[Figure] = []
    for c in cases:
        t = c.data.signals.time - c.data.signals.time[0]
        measured = c.data.signals[c.data.map_output or "nox_ppm"]
        fig_ref = "Fig. 14" if c.scenario == "nox-sdmp" else "Fig. 18"
        out.append(
            Figure(
                f"{c.scenario} (seed {c.seed}): the NOx sensor against the dynamic model with "
                f"the maps learnt over the first {pv.NOX_UPDATE_WINDOW_S:.0f} s, and the "
                f"benchmark — ours for SKF {fig_ref}.",
                series_panels(
                    f"{c.scenario}: NOx prediction with T_NOx,400 ({fig_ref})",
                    t,
                    [
                        (
                            "sensor and KF / SKF / SSKF predictions [ppm]",
                            {"y_NOx (sensor)": measured}
                            | {lab: c.prediction[lab] for lab in ("KF", "SKF", "SSKF")},
                        ),
                        (
                            "sensor and benchmark [ppm]",
                            {"y_NOx (sensor)": measured, "benchmark": c.prediction["benchmark"]},
                        ),
                    ],
                    x_title="time [s]",
                    height_per_panel=300,
                ),
            )
        )
        curves = {lab: r.e_m for lab, r in c.runs.items() if lab not in ("RLS",)}
        first = next(iter(c.runs.values()))
        curves["benchmark"] = np.full(first.t.size, c.benchmark_e_m)
        out.append(
            Figure(
                f"{c.scenario} (seed {c.seed}): e_M(t) of SKF (35), both calibrations — ours "
                "for SKF Fig. 15 (RLS left out when it diverges off the scale: see the table).",
                series_panels(
                    f"{c.scenario}: e_M(t), map learnt until t (Fig. 15)",
                    first.t,
                    [("e_M [ppm]", curves)],
                    x_title="updating time t [s]",
                    height_per_panel=380,
                    dash={"KF Cal (36)": "dash", "SKF Cal (36)": "dash", "benchmark": "dot"},
                ),
            )
        )
        kf = c.runs["KF Cal (36)"].run.history
        skf = c.runs["SKF Cal (36)"].run.history
        th = np.array([h.time_s for h in kf]) - c.data.signals.time[0]
        out.append(
            Figure(
                f"{c.scenario} (seed {c.seed}): variances of elements 126 and 133, KF (solid) "
                "and SKF (dashed), Cal (36) — ours for SKF Fig. 16.",
                series_panels(
                    f"{c.scenario}: variances (Fig. 16)",
                    th,
                    [
                        (
                            f"P{e} [ppm²]",
                            {
                                "KF": np.array([h.variance.ravel()[e - 1] for h in kf]),
                                "SKF": np.array([h.variance.ravel()[e - 1] for h in skf]),
                            },
                        )
                        for e in pv.NOX_FIG16_ELEMENTS
                    ],
                    x_title="time [s]",
                    dash={"SKF": "dash"},
                ),
            )
        )
        true_map = c.data.true_map
        assert true_map is not None
        points = c.data.scoring_points()
        visited = cell_visits(true_map, points) >= 1.0
        est = c.runs["SKF Cal (36)"].run.final.table
        assert est is not None
        shown = np.where(visited, est.values, np.nan)
        out.append(
            Figure(
                f"{c.scenario} (seed {c.seed}): the true end-of-record NOx map, SKF Cal (36)'s "
                "map on the visited cells, and its error (colours span the true map's "
                "range).",
                map_heatmaps(
                    f"{c.scenario}: NOx maps [ppm]",
                    true_map,
                    [
                        ("true (end of record)", true_map.values),
                        ("SKF Cal (36), visited", shown),
                        ("error", shown - true_map.values),
                    ],
                    unit="ppm",
                    diverging=[False, False, True],
                    points=points,
                ),
            )
        )
    return out
