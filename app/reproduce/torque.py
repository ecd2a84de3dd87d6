"""Torque paper §VI–VII: Tables III/VI (UIO, sliding mode, dirty differentiation) and IV/VII
(adaptive laws (50) and (54), κ = 0 and 0.1) on ``torque-si`` and ``torque-rig``.

ISE, MAE and SD are ``mapwise run``'s TQ (60)–(62) over 5–30 s. The paper's ISE cannot be
``∫τ̃² dt`` in seconds: over ``T = 25 s`` that integral lies between ``T·SD²`` and
``T·MAE²``, and the paper's values exceed the upper bound (checked live from the constants),
so ISE is compared by ordering only; MAE and SD are in N·m in both.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

import numpy as np

from app.cli.run import MISMATCH, ScenarioRun, execute_scenario
from app.reproduce import paper_values as pv
from app.reproduce.figures import series_panels
from app.reproduce.report import Figure, Section, Table, Text, num
from estimation.registry import registry
from estimation.scenarios import get_scenario

SCENARIOS = ("torque-si", "torque-rig")
OBSERVERS = ("uio", "smo", "dirty")
LABELS = {"uio": "UIO (14)", "smo": "Sliding mode (21)", "dirty": "Dirty diff. (24)"}
INDICES = (("ise", "ISE"), ("mae", "MAE [N·m]"), ("sd", "SD [N·m]"))
Variant = tuple[str, str, dict[str, float]]  # label, estimator, overrides


def _variants(family: str) -> list[Variant]:
    if family == "observers":
        return [(LABELS[e], e, {}) for e in OBSERVERS]
    return [(label, est, {"kappa": kappa}) for label, est, kappa in pv.ADAPTIVE_VARIANTS]


def _paper_key(family: str, label: str) -> str:
    if family == "observers":
        return next(e for e, lab in LABELS.items() if lab == label)
    return label


def build(seeds: Sequence[int], *, known: Collection[str] | None = None) -> Section:
    """The section for ``seeds``; ``known`` (default: the estimator registry) are the
    estimator names that can run."""
    section = Section(
        key="torque",
        title="Torque paper §VI–VII — Tables III, IV, VI, VII (Figs. 3–6, 9–11)",
        verdict="",
    )
    known = registry() if known is None else known
    section.blocks.append(
        Text(
            "Scenarios `torque-si` (simulation, TQ §VI) and `torque-rig` (rig, TQ §VII), "
            "noise N(0, 20) on speed and load, k = 0.01 s, λ1 = 150 / 350, ℓ = 10 (estimator "
            f"defaults); seeds {', '.join(map(str, seeds))}. Indices over 5–30 s (TQ (60)–(62)). "
            + _ise_note()
        )
    )
    verdicts = []
    for family in ("observers", "adaptive"):
        variants = _variants(family)
        missing = sorted({est for _, est, _ in variants if est not in known})
        if missing:
            verdicts.append(f"{family}: not available ({', '.join(missing)} not registered)")
            section.blocks.append(
                Text(
                    f"**{family.capitalize()}:** not available — {', '.join(missing)} not "
                    "registered in the estimator registry yet."
                )
            )
            continue
        for scenario in SCENARIOS:
            runs = _run(scenario, seeds, variants)
            table_name, figs, paper = pv.TQ_TABLES[(scenario, family)]
            section.blocks.append(_table(scenario, family, seeds, runs, table_name, paper))
            verdict, text = _ordering(scenario, family, seeds, runs, table_name, paper)
            verdicts.append(verdict)
            section.blocks.append(Text(text))
            section.blocks += _figures(scenario, family, runs[seeds[0]], figs)
    section.verdict = "Lowest ISE and SD — " + "; ".join(verdicts) + "."
    return section


def _run(
    scenario: str, seeds: Sequence[int], variants: Sequence[Variant]
) -> dict[int, dict[str, ScenarioRun]]:
    out: dict[int, dict[str, ScenarioRun]] = {}
    for seed in seeds:
        data = get_scenario(scenario).build(seed=seed, mismatch=MISMATCH.get())
        out[seed] = {
            label: execute_scenario(scenario, est, seed=seed, data=data, overrides=overrides)
            for label, est, overrides in variants
        }
    return out


def _ise_note() -> str:
    t = pv.TQ_WINDOW_S[1] - pv.TQ_WINDOW_S[0]
    excess = [
        (name, key, values["ise"] / (t * values["mae"] ** 2))
        for name, table in (
            ("III", pv.TQ_TABLE_III),
            ("IV", pv.TQ_TABLE_IV),
            ("VI", pv.TQ_TABLE_VI),
            ("VII", pv.TQ_TABLE_VII),
        )
        for key, values in table.items()
    ]
    over = [e for e in excess if e[2] > 1.0]
    lo = min(e[2] for e in over) if over else 0.0
    hi = max(e[2] for e in over) if over else 0.0
    return (
        f"The paper's ISE exceeds T·MAE² (the most ∫τ̃² dt can reach over T = {t:g} s) in "
        f"{len(over)} of {len(excess)} entries, by {lo:.1f}× to {hi:.0f}×: it is not ∫τ̃² dt in "
        "seconds (probably a sum over samples at an unstated rate), so ISE is compared by "
        "ordering only. Ours is ∫τ̃² dt [N²·m²·s]."
    )


def _table(
    scenario: str,
    family: str,
    seeds: Sequence[int],
    runs: Mapping[int, Mapping[str, ScenarioRun]],
    table_name: str,
    paper: Mapping[str, Mapping[str, float]],
) -> Table:
    rows = []
    for key, index in INDICES:
        for label, _, _ in _variants(family):
            p = paper[_paper_key(family, label)][key]
            ours = [runs[s][label].result["metrics"].get(key) for s in seeds]
            ratio = ""
            if key != "ise" and all(v is not None for v in ours):
                ratio = f"{np.mean(ours) / p:.2f}"  # type: ignore[arg-type]
            rows.append([index, label, num(p, 5), *(num(v) for v in ours), ratio or "—"])
    return Table(
        f"{scenario}: TQ {table_name} beside ours.",
        [
            "Index",
            "Estimator",
            f"Paper ({table_name})",
            *(f"seed {s}" for s in seeds),
            "ours/paper (mean)",
        ],
        rows,
    )


def _ordering(
    scenario: str,
    family: str,
    seeds: Sequence[int],
    runs: Mapping[int, Mapping[str, ScenarioRun]],
    table_name: str,
    paper: Mapping[str, Mapping[str, float]],
) -> tuple[str, str]:
    """Which estimator has the lowest ISE and SD: the paper's (from its table) and ours per
    seed."""
    labels = [label for label, _, _ in _variants(family)]
    paper_best = {
        key: min(labels, key=lambda lab: paper[_paper_key(family, lab)][key])
        for key in ("ise", "sd")
    }
    ours_best = {
        seed: {
            key: min(
                labels,
                key=lambda lab: runs[seed][lab].result["metrics"].get(key) or np.inf,
            )
            for key in ("ise", "sd")
        }
        for seed in seeds
    }
    same = [s for s in seeds if ours_best[s] == paper_best]
    best_text = (
        f"{paper_best['ise']}"
        if paper_best["ise"] == paper_best["sd"]
        else f"{paper_best['ise']} (ISE) / {paper_best['sd']} (SD)"
    )
    verdict = (
        f"{scenario} {table_name}: as in the paper ({best_text}) on {len(same)} of "
        f"{len(seeds)} seeds"
    )
    lines = [
        f"**{table_name} ordering.** Paper: lowest ISE {paper_best['ise']}, lowest SD "
        f"{paper_best['sd']}. Ours: "
        + "; ".join(f"seed {s}: ISE {ours_best[s]['ise']}, SD {ours_best[s]['sd']}" for s in seeds)
        + "."
    ]
    if len(same) < len(seeds):
        lines.append(
            "Where the ordering differs: our plants are reconstructions (TQ's GT-Power model "
            "and rig data are not available) — a mean-value model with the firing ripple a "
            "test-bed shaft passes, an encoder's speed noise and a load cell's noise, "
            "sampled at 1 kHz (estimation/plants/torque_params.py) — so the balance "
            "between noise amplification (UIO, dirty differentiation, κ > 0) and "
            "tracking lag differs from the paper's."
        )
    if family == "adaptive" and len(same) < len(seeds):
        roams = any(ours_best[s]["ise"] != "(54) κ = 0.1" for s in seeds)
        lines.append(_excitation(runs[seeds[0]], roams=roams))
    claimed = "(54) κ = 0.1"  # issue 5 and docs/algorithms.md §5: best of the four in both tables
    if family == "adaptive" and claimed not in paper_best.values():
        lines.append(
            f"Note: in the paper's own {table_name} the lowest ISE and SD belong to "
            f"{best_text}, not {claimed} as issue 5 and docs/algorithms.md §5 state for both "
            "tables."
        )
    return verdict, " ".join(lines)


def _span(t: np.ndarray, values: np.ndarray) -> tuple[float, float]:
    """Smallest and largest ``values`` over the 5–30 s window of the indices."""
    inside = (t >= t[0] + pv.TQ_WINDOW_S[0]) & (t <= t[0] + pv.TQ_WINDOW_S[1])
    return float(np.min(values[inside])), float(np.max(values[inside]))


def _excitation(runs: Mapping[str, ScenarioRun], *, roams: bool) -> str:
    """Why the adaptive laws differ from the paper, with this seed's numbers: how far the
    parameter estimates of (54) κ = 0.1 and (50) κ = 0 move against the simulator's split of
    τ_e; with ``roams`` (54) κ = 0.1 lost somewhere, and the lack of persistent excitation
    (TQ Lemma 8) is explained."""
    first = next(iter(runs.values()))
    t = first.data.signals.time
    truth = first.data.truth
    parts = []
    for label in ("(54) κ = 0.1", "(50) κ = 0"):
        if label not in runs or "theta1" not in runs[label].final.outputs:
            continue
        out = runs[label].final.outputs
        (a1, b1), (a2, b2) = _span(t, out["theta1"]), _span(t, out["theta2"])
        parts.append(
            f"{label} θ̂1 {num(a1, 3)}…{num(b1, 3)} N·m/rpm, θ̂2 {num(a2, 3)}…{num(b2, 3)} N·m/(kg/s)"
        )
    if not parts:
        return ""
    spans = "; ".join(parts)
    text = f"**Excitation (seed {first.data.seed}).** Over 5–30 s the estimates span {spans}"
    if "theta1" in truth and "theta2" in truth:
        (a1, b1) = _span(t, np.asarray(truth["theta1"]))
        (a2, b2) = _span(t, np.asarray(truth["theta2"]))
        text += (
            f", against the simulator's θ1 {num(a1, 3)}…{num(b1, 3)} N·m/rpm, θ2 "
            f"{num(a2, 3)}…{num(b2, 3)} N·m/(kg/s)"
        )
    text += "."
    if roams:
        text += (
            " N and ṁ_ai move together (at constant speed they are proportional), so the data "
            "excite Θ along one direction only and TQ Lemma 8's persistent excitation fails: "
            "the time-varying gain K ≈ P⁻¹ of (54) lets speed noise, which enters both Φ_f "
            "and J(N − N_f)/k, move Θ̂ along the other direction, and κ > 0 adds the "
            "instantaneous noise of W2 to it, while ΦΘ̂ still fits at the operating point. "
            "τ̂ = ΦΘ̂ then carries θ̂1 times the speed noise. κ > 0 still lowers the error "
            "below 10 Hz, as TQ §VI says, but raises it above 10 Hz, where most of our plant's "
            "5–30 s error lies (the firing ripple, the speed noise). More excitation from the "
            "plant does not change that: induction pulsation in ṁ_ai, even scaled 20×, leaves "
            "(54) κ = 0.1 behind (50) (docs/estimators.md#torque-results)."
        )
    return text + (
        " (50) with ṁ_ai in kg/s and Γ = diag(0.1, 100) moves θ̂2 at the rate Γ2·ṁ_ai²/ℓ, "
        "i.e. hardly at all (its span above): it adapts θ̂1 alone, which cannot roam but "
        "cannot follow a changing θ2 either."
    )


def _window_range(
    t: np.ndarray, values: np.ndarray, *, around: np.ndarray | None = None
) -> tuple[float, float] | None:
    """A y range showing ``values`` over the 5–30 s window: ``±1.1 max|values|``, or with
    ``around`` (the truth) its span widened by ``1.1 max|values − around|``."""
    inside = (t >= t[0] + pv.TQ_WINDOW_S[0]) & (t <= t[0] + pv.TQ_WINDOW_S[1])
    centre = np.zeros_like(values) if around is None else around
    e = (values - centre)[inside]
    e = e[np.isfinite(e)]
    if e.size == 0:
        return None
    bound = 1.1 * float(np.max(np.abs(e)))
    lo = hi = 0.0
    if around is not None:
        lo, hi = float(around[inside].min()), float(around[inside].max())
    return (lo - bound, hi + bound) if hi - lo + bound > 0 else None


def _figures(
    scenario: str, family: str, runs: Mapping[str, ScenarioRun], figs: str
) -> list[Figure]:
    first = next(iter(runs.values()))
    data = first.data
    seed = data.seed
    t = data.signals.time
    truth = data.scored_series["torque_nm"]
    estimates = {label: r.final.outputs["torque_nm"] for label, r in runs.items()}
    out = [
        Figure(
            f"{scenario} (seed {seed}): effective torque estimates against the truth — ours "
            f"for TQ {figs} (estimates); y axes span the 5–30 s window (Autoscale shows the "
            "start-up).",
            series_panels(
                f"{scenario}: torque estimation ({figs})",
                t,
                [(label, {label: est, "true τ_e": truth}) for label, est in estimates.items()],
                x_title="time [s]",
                y_title="N·m",
                y_ranges=[_window_range(t, est, around=truth) for est in estimates.values()],
            ),
        ),
        Figure(
            f"{scenario} (seed {seed}): estimation errors τ_e − τ̂_e — ours for TQ {figs} "
            "(errors). Each y axis spans the errors over the 5–30 s window of the indices; "
            "the start-up transient (Θ̂(0) = 0, zero filter states) runs off the scale: "
            "the Autoscale button shows it.",
            series_panels(
                f"{scenario}: torque estimation errors ({figs})",
                t,
                [(label, {label: truth - est}) for label, est in estimates.items()],
                x_title="time [s]",
                y_title="N·m",
                y_ranges=[_window_range(t, truth - est) for est in estimates.values()],
            ),
        ),
    ]
    if family == "adaptive":
        panels = []
        for name, unit in (("theta1", "N·m/rpm"), ("theta2", "N·m/(kg/s)")):
            traces = {"true": np.asarray(data.truth[name])} if name in data.truth else {}
            traces |= {
                label: r.final.outputs[name] for label, r in runs.items() if name in r.final.outputs
            }
            panels.append((f"{name} [{unit}]", traces))
        pe = {
            label: r.final.outputs["pe_lambda_min"]
            for label, r in runs.items()
            if "pe_lambda_min" in r.final.outputs
        }
        if pe:
            panels.append(("λ_min(P), persistent excitation (TQ Remark 9)", pe))
        out.append(
            Figure(
                f"{scenario} (seed {seed}): the time-varying parameters θ1, θ2 against the "
                "simulator's split of τ_e, and the excitation monitor λ_min(P).",
                series_panels(
                    f"{scenario}: adaptive-law parameters",
                    t,
                    panels,
                    x_title="time [s]",
                ),
            )
        )
    return out
