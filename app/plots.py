"""Self-contained Plotly pages for eyeballing a scenario (no CDN: Plotly.js is inlined from the
installed ``plotly`` package, so the page works offline)."""

from __future__ import annotations

from collections.abc import Sequence
from html import escape
from pathlib import Path

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from estimation.scenarios import ScenarioData
from estimation.table import Table

MAX_POINTS = 20_000  # per trace; longer records are decimated for the browser's sake


def scenario_page(data: ScenarioData, path: str | Path) -> None:
    """Every measured channel against time, then the true map (heatmap) with the operating
    points drawn over it."""
    names = data.signals.names
    has_map = data.true_map is not None and data.true_map.ndim in (1, 2)
    rows = len(names) + (1 if has_map else 0)
    titles = [f"{n} [{data.signals.units.get(n) or '-'}]" for n in names]
    if has_map:
        titles.append("true map with the operating points")
    heights = [1.0] * len(names) + ([2.0] if has_map else [])
    fig = make_subplots(
        rows=rows,
        cols=1,
        subplot_titles=titles,
        vertical_spacing=0.35 / rows,
        row_heights=heights,
    )
    step = max(1, len(data.signals) // MAX_POINTS)
    t = data.signals.time[::step]
    for row, name in enumerate(names, start=1):
        fig.add_trace(
            go.Scattergl(x=t, y=data.signals[name][::step], name=name, mode="lines"),
            row=row,
            col=1,
        )
        fig.update_xaxes(title_text="time [s]", row=row, col=1)
    if has_map:
        assert data.true_map is not None
        _add_map(fig, data.true_map, data.scoring_points()[::step], row=rows)
    fig.update_layout(
        title=f"{data.scenario} (seed {data.seed})",
        height=260 * rows,
        showlegend=False,
        template="plotly_white",
    )
    fig.write_html(str(path), include_plotlyjs=True, full_html=True)


def offline_page(
    title: str, parts: Sequence[str | go.Figure], path: str | Path, *, css: str = ""
) -> None:
    """One self-contained page: HTML fragments and figures in order, Plotly.js inlined once
    in the head (from the installed package: no CDN, works offline)."""
    from plotly.offline import get_plotlyjs

    body = [
        part.to_html(full_html=False, include_plotlyjs=False, config={"responsive": True})
        if isinstance(part, go.Figure)
        else part
        for part in parts
    ]
    Path(path).write_text(
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{escape(title)}</title>\n"
        f'<script type="text/javascript">{get_plotlyjs()}</script>\n'
        f"<style>{css}</style>\n</head>\n<body>\n" + "\n".join(body) + "\n</body>\n</html>\n",
        encoding="utf-8",
    )


def _add_map(fig: go.Figure, table: Table, points: np.ndarray, *, row: int) -> None:
    axes = table.axes
    if table.ndim == 1:
        fig.add_trace(
            go.Scatter(x=axes[0].breakpoints, y=table.values, mode="lines+markers"), row=row, col=1
        )
        fig.update_xaxes(title_text=f"{axes[0].name} [{axes[0].unit}]", row=row, col=1)
        return
    fig.add_trace(
        go.Heatmap(
            x=axes[1].breakpoints,
            y=axes[0].breakpoints,
            z=table.values,
            colorscale="Viridis",
            colorbar={"len": 1.8 / (row + 1), "y": 0.9 / (row + 1), "yanchor": "middle"},
        ),
        row=row,
        col=1,
    )
    fig.add_trace(
        go.Scattergl(
            x=points[:, 1], y=points[:, 0], mode="markers", marker={"size": 2, "color": "white"}
        ),
        row=row,
        col=1,
    )
    fig.update_xaxes(title_text=f"{axes[1].name} [{axes[1].unit}]", row=row, col=1)
    fig.update_yaxes(title_text=f"{axes[0].name} [{axes[0].unit}]", row=row, col=1)
