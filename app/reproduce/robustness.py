"""Robustness study: every headline figure against model mismatch and sensor noise level.

Modelled on the EKF paper's robustness study: the same estimators, settings and seeds, the
plant moved away from what the estimators assume in two directions —

- **mismatch** ``none`` / ``nominal`` / ``severe`` (docs/fidelity.md) at the stated noise;
- **noise level**: every sensor noise σ of the log multiplied by ``0.5`` / ``1`` / ``2``
  (:meth:`estimation.scenarios.Scenario.build` ``noise_scale``) at ``nominal`` mismatch,
  the estimators' own σ settings left as configured, so the study shows robustness to an
  unexpected noise level.

The five cells of :data:`CELLS` are that cross (not the 3 × 3 grid), each on the report's
seeds. Each estimator's literal paper form is reported beside mapwise's modified form: the
LPV law with Γ = 200 I (levels none and nominal) and the EKF with the paper's diagonal
covariance cap against the PSD-preserving limit. The figures are
:mod:`app.reproduce.fidelity`'s, the same as docs/fidelity.md's table; the section also
carries them as data for ``report.json``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np
import plotly.graph_objects as go
from plotly.colors import qualitative
from plotly.subplots import make_subplots

from app.reproduce import fidelity
from app.reproduce.report import Figure, Section, Table, Text
from app.reproduce.runner import parse_choices


@dataclass(frozen=True, slots=True)
class Cell:
    """One column of the study: a mismatch level and a noise scale."""

    level: str
    noise_scale: float

    @property
    def label(self) -> str:
        return fidelity.column_of({"level": self.level, "noise_scale": self.noise_scale})


CELLS: tuple[Cell, ...] = (
    Cell("none", 1.0),
    Cell("nominal", 1.0),
    Cell("severe", 1.0),
    Cell("nominal", 0.5),
    Cell("nominal", 2.0),
)
PARTS: tuple[str, ...] = ("lpv", "lpv-literal", "ekf", "ekf-literal", "nox", "torque")
"""The :data:`app.reproduce.fidelity.PARTS` the study runs (every headline figure)."""
SELECTED_PARTS: ContextVar[tuple[str, ...]] = ContextVar("robustness_parts", default=PARTS)
"""The parts :func:`build` runs (``mapwise reproduce --robustness-parts`` narrows them)."""

MISMATCH_AXIS = tuple(c for c in CELLS if c.noise_scale == 1.0)
NOISE_AXIS = tuple(sorted((c for c in CELLS if c.level == "nominal"), key=lambda c: c.noise_scale))


def parse_parts(text: str | None) -> tuple[str, ...]:
    """``"nox,torque"`` → those parts in :data:`PARTS` order; ``None`` → all; unknown names
    are an error naming the choices."""
    if text is None:
        return PARTS
    return parse_choices(text, PARTS, "--robustness-parts", "part")


def run(
    seeds: Sequence[int],
    *,
    cells: Sequence[Cell] = CELLS,
    parts: Sequence[str] = PARTS,
    progress: Callable[[str], None] | None = None,
) -> list[fidelity.Record]:
    """The figures of every cell and seed: records ``{"level", "noise_scale", "seed",
    "figures"}`` as ``scripts/fidelity.py`` writes them."""
    records = []
    for cell in cells:
        for seed in seeds:
            figures: dict[str, float] = {}
            for part in parts:
                with np.errstate(all="ignore"):
                    figures |= fidelity.PARTS[part](cell.level, seed, cell.noise_scale)
            records.append(
                {
                    "level": cell.level,
                    "noise_scale": cell.noise_scale,
                    "seed": seed,
                    "figures": figures,
                }
            )
            if progress is not None:
                progress(f"robustness: {cell.label}, seed {seed}")
    return records


def table(records: list[fidelity.Record], cells: Sequence[Cell] = CELLS) -> Table:
    """Headline figure × cell: seed mean (range where more than one seed)."""
    columns = tuple(c.label for c in cells)
    rows = fidelity.headline_rows(fidelity.collect(records), columns)
    seeds = sorted({int(r["seed"]) for r in records})
    return Table(
        "Every headline figure against mismatch level (noise × 1) and noise level (nominal), "
        f"seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}: seed mean "
        "(range). LPV in %, EKF in g/s, NOx in ppm, torque ISE in N²·m²·s. “paper's law/cap” "
        "rows are the literal paper forms.",
        ["figure", *columns],
        [[label, *cells_] for label, cells_ in rows],
    )


def figure(records: list[fidelity.Record]) -> go.Figure:
    """Each headline figure relative to its (nominal, noise × 1) value, against mismatch
    (left) and noise level (right); log y axis, one line per figure."""
    rows = fidelity.collect(records)
    fig = make_subplots(
        rows=1,
        cols=2,
        subplot_titles=("against mismatch (noise × 1)", "against noise level (nominal)"),
        shared_yaxes=True,
    )
    reference = Cell("nominal", 1.0).label
    for i, (label, pattern, _unit) in enumerate(fidelity.HEADLINE):
        for key in fidelity.expand(pattern):
            base = _mean(rows.get(key, {}).get(reference))
            if base is None or base == 0.0:
                continue
            name = label if len(fidelity.expand(pattern)) == 1 else f"{label}: {key}"
            for col, axis in ((1, MISMATCH_AXIS), (2, NOISE_AXIS)):
                x = [c.level if col == 1 else f"× {c.noise_scale:g}" for c in axis]
                y = [_ratio(rows.get(key, {}).get(c.label), base) for c in axis]
                fig.add_trace(
                    go.Scatter(
                        x=x,
                        y=y,
                        mode="lines+markers",
                        name=name,
                        legendgroup=key,
                        showlegend=col == 1,
                        line={"color": _COLOURS[i % len(_COLOURS)]},
                    ),
                    row=1,
                    col=col,
                )
    fig.update_yaxes(type="log", title_text="figure / its nominal value [-]", row=1, col=1)
    fig.update_layout(height=620, legend={"font": {"size": 10}})
    return fig


_COLOURS = tuple(qualitative.Dark24)


def _mean(values: list[float] | None) -> float | None:
    if not values:
        return None
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else None


def _ratio(values: list[float] | None, base: float) -> float | None:
    mean = _mean(values)
    return None if mean is None else mean / base


def verdict(records: list[fidelity.Record]) -> str:
    """The headline of the study in one line: how much the worst cell moves the LPV, EKF and
    NOx figures against nominal."""
    rows = fidelity.collect(records)
    reference = Cell("nominal", 1.0).label
    parts = []
    for what, key in (
        ("LPV WHTC-600 s MRE", "lpv/maf-whtc/segment"),
        ("EKF Map RMSE", "ekf/ekf-map"),
        ("torque-si UIO ISE", "torque/torque-si/uio/ise"),
        ("NOx KF held-out RMSE", "nox/kf"),
    ):
        base = _mean(rows.get(key, {}).get(reference))
        severe = _mean(rows.get(key, {}).get(Cell("severe", 1.0).label))
        loud = _mean(rows.get(key, {}).get(Cell("nominal", 2.0).label))
        if base and severe is not None and loud is not None:
            parts.append(f"{what} ×{severe / base:.2g} at severe, ×{loud / base:.2g} at noise × 2")
    return "; ".join(parts) + " (against nominal)" if parts else "no figures"


def _airpath_logging() -> str:
    from estimation.scenarios import get_scenario

    return get_scenario("maf-whtc").logging


def _cut_note() -> str:
    cut = fidelity.DURATION_S.get()
    if cut is None:
        return ""
    return (
        f" Every scenario is cut to its first {cut:g} s (`--robustness-duration`), the papers' "
        "segments with it: not the figures of the whole records."
    )


def build(seeds: Sequence[int]) -> Section:
    """The report section (run with ``mapwise reproduce --robustness``)."""
    records = run(seeds, parts=SELECTED_PARTS.get())
    section = Section(key="robustness", title="Robustness study", verdict=verdict(records))
    section.blocks += [
        Text(
            "The estimators as configured, on plants moved away from what they assume: model "
            "mismatch none / nominal / severe (docs/fidelity.md) at the stated sensor noise, "
            "and every sensor noise σ of the logs × 0.5 / 1 / 2 at nominal mismatch, the "
            "estimators' σ settings unchanged (`noise_scale`, `mapwise run --noise-scale`). "
            "Literal paper forms beside mapwise's: the LPV law Γ = 200 I (none and nominal "
            "only) and the EKF paper's diagonal covariance cap P_ii ← min(P_ii, P0_ii) "
            "(`limit = diag`) against the PSD-preserving limit. The same figures over held-out "
            "seeds: `scripts/fidelity.py` (docs/fidelity.md). Logging of the LPV and EKF "
            f"figures (`Scenario.logging`): {_airpath_logging()} at nominal and severe (at none "
            "the earlier logging: ten-reading means on the 2-D scenarios, single readings on "
            "`maf-1d-whtc`); the rows marked “single readings” log one reading per sample. NOx "
            "and torque log single readings." + _cut_note()
        ),
        table(records),
        Figure(
            "Each headline figure relative to its nominal value, against mismatch and noise "
            "level (log scale).",
            figure(records),
        ),
    ]
    section.data = {
        "cells": [{"level": c.level, "noise_scale": c.noise_scale} for c in CELLS],
        "parts": list(SELECTED_PARTS.get()),
        "duration_s": fidelity.DURATION_S.get(),
        "records": records,
    }
    return section
