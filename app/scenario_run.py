"""``mapwise run``: an estimator on a named scenario, scored against the truth.

With ``--json`` it prints (a contract)::

    {"scenario", "estimator", "seed", "config", "metrics": {...}, "timing": {"estimate_s"},
     "map": <the mapwise adapt document>}        # "map" for map estimators only

Map metrics: ``rmse`` and ``max_abs_error`` against the true map on visited cells,
``mean_relative_error`` (LPV §4 as defined in ALGORITHMS.md §3), ``coverage``; plus
``output_rmse``, the RMS of the measured minus predicted output over accepted samples.

Where the scenario declares a true series that the estimator also outputs, it is scored too:
the effective torque ``torque_nm`` by TQ (60)–(62) over 5–30 s (``ise``, ``mae``, ``sd``), any
other series (e.g. the compressor flow ``w_c_kg_s`` of the EKF observers) by its ``rmse``,
which then takes the ``rmse`` key (a map's own RMSE moves to ``map_rmse``).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.adapt import map_document
from estimation.errors import ConfigError
from estimation.estimator import Estimator, Snapshot, get_spec
from estimation.metrics import map_metrics, output_metrics, torque_metrics
from estimation.scenarios import ScenarioData, get_scenario


def parse_set(items: list[str]) -> dict[str, Any]:
    """``key=value`` overrides; dotted keys reach nested config (``sensor.lag=0.9``).

    A value is read as JSON when it parses (numbers, lists, ``null``, ``true``), else as a
    string.
    """
    overrides: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r}: expected key=value")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        node = overrides
        parts = key.strip().split(".")
        for part in parts[:-1]:
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise ConfigError(f"--set {item!r}: {part!r} is not a section")
            node = child
        node[parts[-1]] = value
    return overrides


def merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``overrides`` applied recursively (a ``null`` section removes it)."""
    out = dict(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out


def run_scenario(
    scenario_name: str,
    estimator_name: str,
    *,
    seed: int = 0,
    overrides: dict[str, Any] | None = None,
    duration_s: float | None = None,
) -> dict[str, Any]:
    """Build the scenario, run the estimator over it, and score the result."""
    return execute_scenario(
        scenario_name, estimator_name, seed=seed, overrides=overrides, duration_s=duration_s
    ).result


@dataclass(frozen=True, slots=True, eq=False)
class ScenarioRun:
    """A scored run with what produced it, for reports and plots.

    ``result`` is what :func:`run_scenario` returns; ``final`` the last snapshot with its
    ``outputs`` and ``status`` covering the whole record; ``history`` (only with ``every``)
    the snapshot after each chunk, without state or outputs (time, table, variance).
    """

    result: dict[str, Any]
    data: ScenarioData
    final: Snapshot
    history: tuple[Snapshot, ...] = ()


def execute_scenario(
    scenario_name: str,
    estimator_name: str,
    *,
    seed: int = 0,
    overrides: dict[str, Any] | None = None,
    duration_s: float | None = None,
    data: ScenarioData | None = None,
    every: int | None = None,
) -> ScenarioRun:
    """:func:`run_scenario` keeping the data and the final snapshot.

    ``data``: a realisation of the scenario already built (same name and seed), reused
    instead of simulating again. ``every``: run in chunks of that many samples and keep the
    snapshot after each (resuming equals the uninterrupted run, so the score is the same).
    """
    scenario = get_scenario(scenario_name)
    spec = get_spec(estimator_name)
    config = merge(scenario.default_config(estimator_name), overrides or {})
    estimator = spec.build(config)
    if data is None:
        data = scenario.build(seed=seed, duration_s=duration_s)
    elif data.scenario != scenario.name or data.seed != seed:
        raise ConfigError(
            f"data of {data.scenario!r} seed {data.seed} given for {scenario.name!r} seed {seed}"
        )
    t0 = time.perf_counter()
    final, history = _run_chunked(estimator, data, every)
    estimate_s = time.perf_counter() - t0
    result: dict[str, Any] = {
        "scenario": scenario.name,
        "estimator": spec.name,
        "seed": seed,
        "config": estimator.config.model_dump(mode="json"),
        "metrics": {},
        "timing": {"estimate_s": estimate_s},
    }
    if final.table is not None and data.true_map is not None:
        metrics = map_metrics(final.table, data.true_map, data.scoring_points())
        if data.scored_series:
            metrics["map_rmse"] = metrics.pop("rmse")
        residual = final.outputs.get("residual")
        if residual is not None and final.status is not None:
            metrics["output_rmse"] = output_metrics(residual[final.status == 0])["rmse"]
        result["map"] = map_document(final, samples=len(data.signals), estimate_s=estimate_s)
    else:
        metrics = {}
    metrics |= series_metrics(data, final.outputs)
    result["metrics"] = {k: _finite_or_none(v) for k, v in metrics.items()}
    return ScenarioRun(result=result, data=data, final=final, history=history)


def _run_chunked(
    estimator: Estimator, data: ScenarioData, every: int | None
) -> tuple[Snapshot, tuple[Snapshot, ...]]:
    if every is None:
        return estimator.fit(data.signals), ()  # type: ignore[attr-defined]
    snapshots = list(estimator.run(data.signals, every=every))
    last = snapshots[-1]
    outputs = {name: np.concatenate([s.outputs[name] for s in snapshots]) for name in last.outputs}
    status = None
    if last.status is not None:
        status = np.concatenate([s.status for s in snapshots if s.status is not None])
    final = dataclasses.replace(last, chunk_start=0, outputs=outputs, status=status)
    history = tuple(dataclasses.replace(s, state=None, outputs={}, status=None) for s in snapshots)
    return final, history


TORQUE_WINDOW_S = (5.0, 30.0)  # TQ §VI: indices over 5–30 s


def series_metrics(data: ScenarioData, outputs: dict[str, np.ndarray]) -> dict[str, float]:
    """Score every estimator output the scenario has a true series for."""
    metrics: dict[str, float] = {}
    for name, truth in data.scored_series.items():
        estimate = outputs.get(name)
        if estimate is None or estimate.shape != truth.shape:
            continue
        error = truth - estimate
        if name == "torque_nm":
            t = data.signals.time
            window = (t[0] + TORQUE_WINDOW_S[0], min(t[0] + TORQUE_WINDOW_S[1], t[-1]))
            metrics |= torque_metrics(t, error, window_s=window)
        else:
            metrics["rmse"] = output_metrics(error)["rmse"]
    return metrics


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None
