"""``mapwise adapt``: learn a look-up table from a logged drive with one map filter.

The JSON document it writes is a contract used by scripts outside the repository::

    {"estimator", "axes": [{"name", "unit", "breakpoints"}], "values", "variance",
     "samples", "rejected": {reason: count}, "timing": {"load_s", "estimate_s"}}

``values`` and ``variance`` are nested lists in axis order (``variance`` is ``null`` for the
covariance-free filters). Extra keys (``output``, ``accepted``, ``config``) may be added;
existing ones never change.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.io.csv_files import read_csv
from estimation.errors import ConfigError
from estimation.estimator import Snapshot, get_spec

MAP_FILTERS = ("kf", "skf", "sskf", "rls", "nlms")

# Which options each filter understands; anything else is a usage error, not silently ignored.
_OPTIONS: dict[str, set[str]] = {
    "kf": {"sigma_w", "sigma_v", "p0", "theta0", "limit", "sensor"},
    "skf": {"sigma_w", "sigma_v", "p0", "theta0", "limit", "sensor"},
    "sskf": {"sigma_w", "sigma_v", "theta0"},
    "rls": {"sigma_v", "p0", "theta0", "limit", "forgetting"},
    "nlms": {"sigma_v", "theta0", "mu"},
}
_FLAGS = {
    "sigma_w": "--sigma-w",
    "sigma_v": "--sigma-v",
    "p0": "--p0",
    "theta0": "--theta0",
    "limit": "--limit",
    "sensor": "--lag/--delay-s/--sigma-f",
    "forgetting": "--forgetting",
    "mu": "--mu",
}


@dataclass
class AdaptRequest:
    """What the command line asked for, in config terms."""

    input: Path
    estimator: str
    axes: list[tuple[str, list[float]]]
    output: str
    options: dict[str, Any] = field(default_factory=dict)
    locked: list[list[int]] = field(default_factory=list)
    gate_sigma: float | None = None
    time_column: str | None = None


def parse_axis(text: str) -> tuple[str, list[float]]:
    """``NAME=B1,B2,...`` → ``(NAME, [B1, B2, ...])`` with a message naming the problem."""
    name, sep, rest = text.partition("=")
    if not sep or not name.strip():
        raise ConfigError(f"--axis {text!r}: expected NAME=B1,B2,...")
    try:
        breakpoints = [float(b) for b in rest.split(",") if b.strip()]
    except ValueError:
        raise ConfigError(f"--axis {text!r}: breakpoints must be numbers") from None
    if len(breakpoints) < 2:
        raise ConfigError(f"--axis {name}: needs at least two breakpoints, got {len(breakpoints)}")
    if not all(np.isfinite(breakpoints)):
        raise ConfigError(f"--axis {name}: breakpoints must be finite")
    for i in range(len(breakpoints) - 1):
        if breakpoints[i] >= breakpoints[i + 1]:
            raise ConfigError(
                f"--axis {name}: breakpoints must be strictly increasing "
                f"({breakpoints[i]:g} then {breakpoints[i + 1]:g})"
            )
    return name.strip(), breakpoints


def parse_cells(text: str, ndim: int) -> list[list[int]]:
    """``"i,j;i,j"`` → ``[[i, j], [i, j]]`` (one index per axis, 0-based)."""
    cells = []
    for part in text.split(";"):
        if not part.strip():
            continue
        try:
            cell = [int(i) for i in part.split(",")]
        except ValueError:
            raise ConfigError(f"--lock {text!r}: cells are 0-based integers 'i,j;i,j'") from None
        if len(cell) != ndim:
            raise ConfigError(f"--lock: cell {part.strip()!r} needs {ndim} indices, one per axis")
        cells.append(cell)
    return cells


def build_config(request: AdaptRequest, units: dict[str, str]) -> dict[str, Any]:
    """The filter config dict of a request (units come from the log)."""
    allowed = _OPTIONS[request.estimator]
    for key in request.options:
        if key not in allowed:
            raise ConfigError(f"{_FLAGS[key]} does not apply to --estimator {request.estimator}")
    return {
        "axes": [
            {"name": name, "breakpoints": bps, "unit": units.get(name, "")}
            for name, bps in request.axes
        ],
        "output": request.output,
        "output_unit": units.get(request.output, ""),
        "locked": request.locked,
        "gate_sigma": request.gate_sigma,
        **request.options,
    }


def adapt(request: AdaptRequest) -> dict[str, Any]:
    """Load the log, run the filter over it and return the contract document."""
    spec = get_spec(request.estimator)
    if request.estimator not in MAP_FILTERS:
        raise ConfigError(f"--estimator must be one of {', '.join(MAP_FILTERS)}")
    columns = [name for name, _ in request.axes] + [request.output]
    t0 = time.perf_counter()
    log = read_csv(request.input, columns=columns, time_column=request.time_column)
    load_s = time.perf_counter() - t0
    sensor = request.options.get("sensor")
    if sensor and sensor.get("delay_s") and log.time_column is None:
        raise ConfigError("--delay-s needs a time column in seconds: pass --time COLUMN")
    estimator = spec.build(build_config(request, log.signals.units))
    t0 = time.perf_counter()
    final = estimator.fit(log.signals)  # type: ignore[attr-defined]
    estimate_s = time.perf_counter() - t0
    return map_document(final, samples=len(log.signals), load_s=load_s, estimate_s=estimate_s)


def map_document(
    snapshot: Snapshot, *, samples: int, load_s: float | None = None, estimate_s: float
) -> dict[str, Any]:
    """The ``mapwise adapt`` JSON document of a final snapshot."""
    table = snapshot.table
    assert table is not None
    rejected = {k: int(v) for k, v in snapshot.rejected.items()}
    timing = (
        {"estimate_s": estimate_s}
        if load_s is None
        else {
            "load_s": load_s,
            "estimate_s": estimate_s,
        }
    )
    return {
        "estimator": snapshot.estimator,
        "axes": [a.to_dict() for a in table.axes],
        "values": table.values.tolist(),
        "variance": None if snapshot.variance is None else snapshot.variance.tolist(),
        "samples": samples,
        "accepted": samples - sum(rejected.values()),
        "rejected": rejected,
        "timing": timing,
    }


def format_table(document: dict[str, Any]) -> str:
    """A human-readable view of a map document (rows: first axis, columns: second)."""
    axes = document["axes"]
    values = np.asarray(document["values"])
    head = f"{document['estimator']}: {document['samples']} samples"
    rejected = ", ".join(f"{k} {v}" for k, v in document["rejected"].items() if v)
    head += f" ({rejected} rejected)" if rejected else ""
    if values.ndim == 1:
        a = axes[0]
        rows = [f"{a['name']} [{a['unit']}]    value"]
        rows += [f"{b:>10g}  {v:>10.4g}" for b, v in zip(a["breakpoints"], values, strict=True)]
        return "\n".join([head, *rows])
    if values.ndim != 2:
        return f"{head}\n(values of a {values.ndim}-D table: use --json)"
    a, b = axes
    width = 9
    lines = [head, f"rows: {a['name']} [{a['unit']}], columns: {b['name']} [{b['unit']}]"]
    lines.append(" " * width + "".join(f"{x:>{width}g}" for x in b["breakpoints"]))
    for bp, row in zip(a["breakpoints"], values, strict=True):
        lines.append(f"{bp:>{width}g}" + "".join(f"{v:>{width}.4g}" for v in row))
    return "\n".join(lines)
