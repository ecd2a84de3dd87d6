"""Plotly figures the report sections share: time series, map heatmaps and surfaces.

Long records are decimated to at most ``MAX_POINTS`` per trace (the page stays light); map
panels share one colour scale per figure unless they are error maps.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from estimation.table import Table

MAX_POINTS = 3000
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#17becf")


def stride(n: int, max_points: int = MAX_POINTS) -> int:
    """Step that keeps at most ``max_points`` of ``n`` samples."""
    return max(1, -(-n // max_points))


def series_panels(
    title: str,
    x: np.ndarray,
    panels: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    *,
    x_title: str,
    y_title: str = "",
    height_per_panel: int = 230,
    dash: Mapping[str, str] | None = None,
    y_ranges: Sequence[tuple[float, float] | None] | None = None,
) -> go.Figure:
    """One subplot per ``(panel title, {trace name: y})``, all against ``x``; a trace name
    keeps its colour across panels. ``y_ranges`` fixes a panel's initial y range (``None``:
    autorange); what lies outside stays in the data, a double click shows it."""
    fig = make_subplots(
        rows=len(panels),
        cols=1,
        shared_xaxes=True,
        subplot_titles=[p[0] for p in panels],
        vertical_spacing=min(0.08, 0.3 / max(len(panels), 1)),
    )
    names: list[str] = []
    for row, (_, traces) in enumerate(panels, start=1):
        for name, y in traces.items():
            y = np.asarray(y, dtype=np.float64)
            step = stride(y.size)
            first = name not in names
            if first:
                names.append(name)
            fig.add_trace(
                go.Scatter(
                    x=x[: y.size : step],
                    y=y[::step],
                    name=name,
                    legendgroup=name,
                    showlegend=first,
                    mode="lines",
                    line={
                        "color": COLORS[names.index(name) % len(COLORS)],
                        "width": 1.3,
                        "dash": (dash or {}).get(name, "solid"),
                    },
                ),
                row=row,
                col=1,
            )
        fig.update_yaxes(title_text=y_title, row=row, col=1)
        if y_ranges is not None and y_ranges[row - 1] is not None:
            fig.update_yaxes(range=list(y_ranges[row - 1]), row=row, col=1)  # type: ignore[arg-type]
    fig.update_xaxes(title_text=x_title, row=len(panels), col=1)
    fig.update_layout(
        title=title,
        height=120 + height_per_panel * len(panels),
        template="plotly_white",
        legend={"orientation": "h", "y": -0.08 if len(panels) > 1 else -0.25},
        margin={"t": 80},
    )
    return fig


def map_heatmaps(
    title: str,
    like: Table,
    panels: Sequence[tuple[str, np.ndarray]],
    *,
    unit: str,
    diverging: Sequence[bool] = (),
    points: np.ndarray | None = None,
) -> go.Figure:
    """Side-by-side heatmaps of 2-D maps on ``like``'s grid (``NaN`` cells left blank).

    Panels not flagged ``diverging`` share one colour bar whose range is the first panel's
    (the reference: other maps saturate where they leave it); diverging (error) panels share
    a second one centred on zero. ``points`` (n, 2) in axis order are drawn over the first
    panel.
    """
    ax0, ax1 = like.axes
    fig = make_subplots(
        rows=1, cols=len(panels), subplot_titles=[p[0] for p in panels], horizontal_spacing=0.05
    )
    flags = list(diverging) + [False] * (len(panels) - len(diverging))
    reference = np.asarray(panels[0][1], dtype=np.float64)
    lo, hi = _finite_range(reference)
    errors = [np.asarray(v, dtype=np.float64) for (_, v), d in zip(panels, flags, strict=True) if d]
    bound = max((_finite_range(np.abs(e))[1] for e in errors), default=1.0) or 1.0
    for col, ((_, values), is_error) in enumerate(zip(panels, flags, strict=True), start=1):
        fig.add_trace(
            go.Heatmap(
                x=ax1.breakpoints,
                y=ax0.breakpoints,
                z=np.asarray(values, dtype=np.float64),
                coloraxis="coloraxis2" if is_error else "coloraxis",
                hovertemplate=f"{ax1.name}=%{{x}}<br>{ax0.name}=%{{y}}<br>%{{z:.4g}} {unit}"
                "<extra></extra>",
            ),
            row=1,
            col=col,
        )
        fig.update_xaxes(title_text=f"{ax1.name} [{ax1.unit}]", row=1, col=col)
    fig.update_yaxes(title_text=f"{ax0.name} [{ax0.unit}]", row=1, col=1)
    if points is not None:
        step = stride(len(points), 2000)
        fig.add_trace(
            go.Scattergl(
                x=points[::step, 1],
                y=points[::step, 0],
                mode="markers",
                marker={"size": 2, "color": "white"},
                name="operating points",
                showlegend=False,
            ),
            row=1,
            col=1,
        )
    fig.update_layout(
        title=title,
        height=430,
        template="plotly_white",
        margin={"t": 80, "r": 150},
        coloraxis={
            "colorscale": "Viridis",
            "cmin": lo,
            "cmax": hi,
            "colorbar": {"x": 1.0, "len": 0.9, "thickness": 12, "title": {"text": unit}},
        },
        coloraxis2={
            "colorscale": "RdBu_r",
            "cmin": -bound,
            "cmax": bound,
            "colorbar": {"x": 1.08, "len": 0.9, "thickness": 12, "title": {"text": "error"}},
        },
    )
    if not errors:
        fig.update_layout(coloraxis2_showscale=False)
    return fig


def _finite_range(values: np.ndarray) -> tuple[float, float]:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return 0.0, 1.0
    lo, hi = float(finite.min()), float(finite.max())
    return (lo, hi) if hi > lo else (lo - 0.5, hi + 0.5)


def map_surfaces(
    title: str, like: Table, surfaces: Sequence[tuple[str, np.ndarray]], *, unit: str
) -> go.Figure:
    """The maps as 3-D surfaces in one scene (``NaN`` cells left open)."""
    ax0, ax1 = like.axes
    fig = go.Figure()
    scales = ("Viridis", "Reds", "Blues", "Greens")
    for i, (name, values) in enumerate(surfaces):
        fig.add_trace(
            go.Surface(
                x=ax1.breakpoints,
                y=ax0.breakpoints,
                z=np.asarray(values, dtype=np.float64),
                name=name,
                colorscale=scales[i % len(scales)],
                showscale=False,
                opacity=1.0 if i == 0 else 0.85,
                showlegend=True,
            )
        )
    fig.update_layout(
        title=title,
        height=560,
        template="plotly_white",
        scene={
            "xaxis_title": f"{ax1.name} [{ax1.unit}]",
            "yaxis_title": f"{ax0.name} [{ax0.unit}]",
            "zaxis_title": unit,
        },
    )
    return fig


def curve_1d(
    title: str, x_title: str, y_title: str, curves: Mapping[str, tuple[np.ndarray, np.ndarray]]
) -> go.Figure:
    """Curves ``name → (x, y)`` on one axis (markers where there are few points)."""
    fig = go.Figure()
    for i, (name, (x, y)) in enumerate(curves.items()):
        step = stride(np.asarray(x).size)
        fig.add_trace(
            go.Scatter(
                x=np.asarray(x)[::step],
                y=np.asarray(y)[::step],
                name=name,
                mode="lines+markers" if np.asarray(x).size <= 40 else "markers",
                marker={"size": 4 if np.asarray(x).size > 40 else 7, "color": COLORS[i]},
            )
        )
    fig.update_layout(
        title=title,
        xaxis_title=x_title,
        yaxis_title=y_title,
        height=420,
        template="plotly_white",
    )
    return fig
