"""The scenario's own setup of a simulated dataset, per estimator, as the New-run form fills it.

A dataset simulated from a scenario keeps the scenario's name and, in its truth, the
estimator-side constants drawn for that realisation (``estimator_params``) and the true
map's grid. :func:`dataset_setup` turns them into what a run request needs for each
estimator the scenario applies to (``Scenario.default_config(estimator, data)``, the
papers' settings with the realisation's constants):

- ``table``: the grid (axes and breakpoints) — the scenario config's own axes for the table
  filters, the true map's grid for an observer that adapts a table (LPV), so the run is
  scored against the known truth (the metrics need the truth's grid);
- ``signals``: the columns of its signal roles (``y`` = the scenario's measured output for a
  table filter; an observer's roles at their default columns where the dataset has them);
- ``config``: the rest of the scenario config (the keys a run request fills from ``table``
  and ``signals`` left out).

Estimators the scenario does not apply to are left out; an uploaded log has no setup.
"""

from __future__ import annotations

from typing import Any

from app.db import blobs
from app.db.engine import Database
from app.db.repositories import DatasetRepo
from app.domain import Dataset
from app.services.catalog import TABLE_ROLE, kind_of, needs_table, role_keys, roles
from estimation.registry import registry
from estimation.scenarios import scenarios


def truth_meta(blob: bytes | None) -> dict[str, Any]:
    """The metadata of a stored truth (``app.io.payload.pack_truth``), ``{}`` without one."""
    if blob is None:
        return {}
    _, meta = blobs.unpack_meta(blob)
    return dict(meta)


def dataset_setup(dataset: Dataset, truth: bytes | None) -> dict[str, Any]:
    """``{scenario, seed, mismatch, estimators: {name: {table, signals, config}}}`` of a
    simulated dataset; ``estimators`` is empty for an uploaded log or a scenario no longer
    in the catalog."""
    scenario = scenarios().get(dataset.scenario or "")
    meta = truth_meta(truth) if scenario is not None else {}
    out: dict[str, Any] = {
        "scenario": dataset.scenario,
        "seed": dataset.seed,
        "mismatch": (meta.get("metadata") or {}).get("mismatch"),
        "suggested": list(scenario.suggested) if scenario is not None else [],
        "estimators": {},
    }
    if scenario is None:
        return out
    drawn = {str(k): float(v) for k, v in (meta.get("estimator_params") or {}).items()}
    columns = {c.name for c in dataset.channels}
    true_axes = meta.get("true_map_axes")
    for name, spec in registry().items():
        config = scenario.configs(name, drawn)
        if config is None:
            continue
        out["estimators"][name] = _split(spec, dict(config), columns, true_axes)
    return out


def _split(
    spec: Any, config: dict[str, Any], columns: set[str], true_axes: list[dict[str, Any]] | None
) -> dict[str, Any]:
    """A scenario config as a run request's ``table``, ``signals`` and ``config``."""
    table = None
    signals: dict[str, str] = {}
    if kind_of(spec) == "table-filter":
        signals[TABLE_ROLE] = str(config.get("output", ""))
    else:
        signals = {
            r.role: r.default for r in roles(spec) if r.default is not None and r.default in columns
        }
    if needs_table(spec):
        axes = config.get("axes")
        if axes is None and true_axes and all(a.get("name") in columns for a in true_axes):
            axes = true_axes
        if axes:
            table = {
                "axes": [
                    {
                        "name": a["name"],
                        "breakpoints": [float(b) for b in a["breakpoints"]],
                        "unit": a.get("unit", ""),
                    }
                    for a in axes
                ]
            }
    hidden = role_keys(spec)
    rest = {k: v for k, v in config.items() if k not in hidden}
    return {"table": table, "signals": signals, "config": rest}


def setup_of(db: Database, dataset_id: int) -> dict[str, Any]:
    """:func:`dataset_setup` of stored dataset ``dataset_id`` (a 404 if there is none)."""
    with db.read() as s:
        repo = DatasetRepo(s)
        dataset = repo.get(dataset_id)
        truth = repo.truth(dataset_id) if dataset.scenario else None
    return dataset_setup(dataset, truth)
