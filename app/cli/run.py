"""``mapwise run``: an estimator on a named scenario, scored against the truth.

With ``--json`` it prints (a contract)::

    {"scenario", "estimator", "seed", "mismatch", "logging", "noise_scale",
     "estimator_model", "config", "metrics": {...}, "timing": {"estimate_s"},
     "map": <the map document of app.io.map_json>}        # "map" for map estimators only

``mismatch`` is the level the scenario was built at (``--mismatch``, default ``nominal``;
docs/fidelity.md), ``logging`` the sensor averaging of the log, ``noise_scale`` the factor on
every sensor noise σ of the log (``--noise-scale``, default 1; the estimator's σ settings are
not scaled), ``estimator_model`` every estimator-side model constant beside the plant's.
``--transient-24s`` adds TQ §VI's set-point step at 24 s to ``torque-si``.

Map metrics: ``rmse`` and ``max_abs_error`` against the true map on visited cells,
``mean_relative_error`` (LPV §4 as defined in docs/algorithms.md §3), ``coverage``; plus
``output_rmse``, the RMS of the measured minus predicted output over accepted samples.

Where the scenario declares a true series that the estimator also outputs, it is scored too:
the effective torque ``torque_nm`` by TQ (60)–(62) over 5–30 s (``ise``, ``mae``, ``sd``), any
other series (e.g. the compressor flow ``w_c_kg_s`` of the EKF observers) by its ``rmse``,
which then takes the ``rmse`` key (a map's own RMSE moves to ``map_rmse``).

:func:`execute_scenario` is also what ``mapwise reproduce`` runs the papers' cases with.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.io.map_json import map_document
from app.services.overrides import merge
from estimation.errors import ConfigError
from estimation.estimator import Estimator, Snapshot
from estimation.metrics import score_run
from estimation.mismatch import LEVELS
from estimation.registry import get_spec, names
from estimation.scenarios import ScenarioData, get_scenario, scenarios

MISMATCH: ContextVar[str] = ContextVar("mismatch", default="nominal")
"""The mismatch level :func:`execute_scenario` builds at when not told (``mapwise reproduce
--mismatch`` sets it for a whole report)."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run an estimator on a simulated scenario and score it against the truth",
        description="Run any registered estimator on a named scenario and score it against the "
        "truth. --set key=value reaches any config key (dotted keys for sections, values as "
        "JSON), e.g. --set sigma_w=7 --set sensor.lag=0.9.",
    )
    p.add_argument(
        "--scenario",
        required=True,
        help=f"scenario name: {', '.join(scenarios())} (mapwise simulate --list)",
    )
    p.add_argument("--estimator", required=True, help=f"estimator name: {', '.join(names())}")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--duration", type=float, help="simulate only the first S seconds")
    add_mismatch_arguments(p)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--json", action="store_true", help="print the result document as JSON")
    p.set_defaults(handler=run_command)


def add_mismatch_arguments(p: argparse.ArgumentParser) -> None:
    """``--mismatch``, ``--averaging`` (docs/fidelity.md), ``--noise-scale`` and
    ``--transient-24s`` (:meth:`estimation.scenarios.Scenario.build`)."""
    p.add_argument(
        "--mismatch",
        choices=LEVELS,
        default="nominal",
        help="plant/estimator model mismatch (default nominal; none = the perfect-model runs)",
    )
    p.add_argument(
        "--averaging",
        type=int,
        metavar="N",
        help="air-path scenarios: sensor readings averaged per logged sample (default: the "
        "scenario's logging; 1 = single readings)",
    )
    p.add_argument(
        "--noise-scale",
        type=float,
        default=1.0,
        metavar="S",
        help="multiply every sensor noise σ of the simulated log by S in [0, 100] (default 1; "
        "0 = noise-free); the estimator's σ settings stay as configured",
    )
    p.add_argument(
        "--transient-24s",
        action="store_true",
        help="torque-si: add TQ §VI's set-point step at 24 s (1900 → 2200 rpm)",
    )


def run_command(args: argparse.Namespace) -> int:
    """``mapwise run``: the result document as JSON, or its metrics as text."""
    result = run_scenario(
        args.scenario,
        args.estimator,
        seed=args.seed,
        overrides=parse_set(args.set),
        duration_s=args.duration,
        mismatch=args.mismatch,
        averaging=args.averaging,
        noise_scale=args.noise_scale,
        transient_24s=args.transient_24s,
    )
    if args.json:
        print(json.dumps(result))
        return 0
    noise = "" if result["noise_scale"] == 1.0 else f", noise × {result['noise_scale']:g}"
    print(
        f"{result['estimator']} on {result['scenario']} (seed {result['seed']}, mismatch "
        f"{result['mismatch']}, {result['logging']}{noise}), "
        f"{result['timing']['estimate_s']:.3f} s"
    )
    for key, value in result["metrics"].items():
        print(f"  {key:<22} {'n/a' if value is None else f'{value:.6g}'}")
    return 0


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


def run_scenario(
    scenario_name: str,
    estimator_name: str,
    *,
    seed: int = 0,
    overrides: dict[str, Any] | None = None,
    duration_s: float | None = None,
    mismatch: str | None = None,
    averaging: int | None = None,
    noise_scale: float = 1.0,
    transient_24s: bool = False,
) -> dict[str, Any]:
    """Build the scenario, run the estimator over it, and score the result."""
    return execute_scenario(
        scenario_name,
        estimator_name,
        seed=seed,
        overrides=overrides,
        duration_s=duration_s,
        mismatch=mismatch,
        averaging=averaging,
        noise_scale=noise_scale,
        transient_24s=transient_24s,
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
    mismatch: str | None = None,
    averaging: int | None = None,
    noise_scale: float = 1.0,
    transient_24s: bool = False,
) -> ScenarioRun:
    """:func:`run_scenario` keeping the data and the final snapshot.

    ``data``: a realisation of the scenario already built (same name and seed), reused
    instead of simulating again. ``every``: run in chunks of that many samples and keep the
    snapshot after each (resuming equals the uninterrupted run, so the score is the same).
    ``mismatch`` (default :data:`MISMATCH`'s value, ``"nominal"``), ``averaging``,
    ``noise_scale`` and ``transient_24s``: see :meth:`estimation.scenarios.Scenario.build`.
    The estimator starts from the realisation's config (its drawn model constants), then
    ``overrides``.
    """
    scenario = get_scenario(scenario_name)
    spec = get_spec(estimator_name)
    if data is None:
        level = MISMATCH.get() if mismatch is None else mismatch
        data = scenario.build(
            seed=seed,
            duration_s=duration_s,
            mismatch=level,  # type: ignore[arg-type]
            averaging=averaging,
            noise_scale=noise_scale,
            transient_24s=transient_24s,
        )
    elif data.scenario != scenario.name or data.seed != seed:
        raise ConfigError(
            f"data of {data.scenario!r} seed {data.seed} given for {scenario.name!r} seed {seed}"
        )
    config = merge(scenario.default_config(estimator_name, data=data), overrides or {})
    estimator = spec.build(config)
    t0 = time.perf_counter()
    final, history = _run_chunked(estimator, data, every)
    estimate_s = time.perf_counter() - t0
    result: dict[str, Any] = {
        "scenario": scenario.name,
        "estimator": spec.name,
        "seed": seed,
        "mismatch": data.mismatch,
        "logging": _logging(scenario.logging, data.metadata.get("averaging")),
        "noise_scale": float(data.metadata.get("noise_scale", 1.0)),
        "estimator_model": data.metadata.get("parameters", []),
        "config": estimator.config.model_dump(mode="json"),
        "metrics": {},
        "timing": {"estimate_s": estimate_s},
    }
    if final.table is not None and data.true_map is not None:
        from app.services.truth_map import MAP_QUANTITY

        cfg = result["config"]
        quantity, unit = (
            (cfg["output"], str(cfg.get("output_unit") or ""))
            if cfg.get("output")
            else MAP_QUANTITY.get(spec.name, ("", ""))
        )
        result["map"] = map_document(
            final,
            samples=len(data.signals),
            estimate_s=estimate_s,
            quantity=quantity,
            unit=unit,
        )
    metrics = score_run(final.outputs, final.status, table=final.table, truth=data)
    result["metrics"] = {k: _finite_or_none(v) for k, v in metrics.items()}
    return ScenarioRun(result=result, data=data, final=final, history=history)


def _run_chunked(
    estimator: Estimator, data: ScenarioData, every: int | None
) -> tuple[Snapshot, tuple[Snapshot, ...]]:
    if every is None:
        return estimator.fit(data.signals), ()
    snapshots = list(estimator.run(data.signals, every=every))
    last = snapshots[-1]
    outputs = {name: np.concatenate([s.outputs[name] for s in snapshots]) for name in last.outputs}
    status = None
    if last.status is not None:
        status = np.concatenate([s.status for s in snapshots if s.status is not None])
    final = dataclasses.replace(last, chunk_start=0, outputs=outputs, status=status)
    history = tuple(dataclasses.replace(s, state=None, outputs={}, status=None) for s in snapshots)
    return final, history


def _logging(stated: str, averaging: int | None) -> str:
    if averaging is None:
        return stated
    return "single readings" if averaging == 1 else f"mean of {averaging} readings per sample"


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None
