"""``mapwise tune``: choose an estimator's noise settings from a log that has no truth.

A map filter reads the same CSV log and flags as ``mapwise adapt``; a joint EKF
(``ekf-def``, ``ekf-aug``, ``ekf-map``) reads a CSV log with the default channel names of
:class:`~estimation.observers.ekf_config.EkfChannels` and the EKF's default config, or a
scenario's realisation (``--scenario NAME --seed N [--duration S]``, nominal mismatch) with
the config drawn for it. It prints one JSON document (docs/tuning.md, docs/cli.md)::

    {"estimator", "samples", "parameters": {"sigma_w", "sigma_v"[, "sigma_f"]},
     "start", "log_likelihood", "evaluations", "max_evaluations", "at_bound",
     "innovation": {"samples", "mean_nis", "mean_nis_band", "consistent", "in_band",
                    "innovation_mean", "innovation_rms", "log_likelihood"},
     "holdout": {"unit", "fraction", "fit_samples", "holdout_samples", "scored",
                 "adapted": {"rmse", "mae", "max_abs_error"}, "base": {…}, "innovations"},
     "unit", "timing": {"load_s", "tune_s"}}

``parameters`` are standard deviations in the output's unit (EKF: ``sigma_maf_rel``,
``sigma_maf_abs`` [kg/s] and ``sigma_bias`` [kg/s/√s] or ``sigma_theta`` [1/√s]; its
``holdout`` is :func:`estimation.holdout_ekf.ekf_holdout`'s); the search and its
bounds are those of :mod:`estimation.tuning`.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from app.cli.adapt import (
    AdaptRequest,
    add_filter_arguments,
    build_config,
    parse_axis,
    parse_cells,
)
from app.cli.errors import UsageError
from estimation.holdout import DEFAULT_FIT_FRACTION, holdout_error
from estimation.registry import EstimatorKind, names
from estimation.signals import Signals
from estimation.tuning import (
    DEFAULT_EVALUATIONS,
    EKF_PARAMETERS,
    MAX_EVALUATIONS,
    MAX_SAMPLES,
    tune,
    tune_ekf,
)

EKF_STARTS = ("sigma_maf_rel", "sigma_maf_abs", "sigma_bias", "sigma_theta")
"""The EKF's ``--sigma-*`` starts (which of them a variant tunes: ``EKF_PARAMETERS``)."""
MAP_ONLY = (
    *("axis", "y", "sigma_w", "sigma_v", "sigma_f", "lag", "delay_s", "delay_samples"),
    *("p0", "theta0", "limit", "forgetting", "mu", "lock"),
)
"""Map-filter flags an EKF refuses."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune",
        help="choose a map filter's σw, σv (σf) or an EKF's MAF noise by maximum innovation "
        "likelihood on a log",
        description="Choose a map filter's noise settings, or a joint EKF's MAF noise, from a "
        "CSV log (no truth needed) by maximising the innovation log-likelihood; prints a JSON "
        "document. --sigma-* give the search's starting point. At most "
        f"{MAX_SAMPLES} samples and {MAX_EVALUATIONS} evaluations.",
    )
    p.add_argument("input", type=Path, nargs="?", help="CSV log with a header row")
    p.add_argument(
        "--estimator",
        required=True,
        choices=names(EstimatorKind.MAP_FILTER) + tuple(EKF_PARAMETERS),
    )
    p.add_argument(
        "--axis",
        action="append",
        metavar="NAME=B1,B2,...",
        help="map filters: one per table dimension; NAME is an input column",
    )
    p.add_argument("--y", metavar="COLUMN", help="map filters: the measured table output")
    p.add_argument("--scenario", help="EKF: tune on this scenario's realisation, not a CSV")
    p.add_argument("--seed", type=int, help="EKF with --scenario: its seed (default 0)")
    p.add_argument("--duration", type=float, help="EKF with --scenario: seconds of it")
    for name in EKF_STARTS:
        flag = "--" + name.replace("_", "-")
        p.add_argument(flag, type=float, help=f"EKF: start of {name} (default: the config's)")
    p.add_argument("--sigma-w", type=float, help="start of σw (default: σv's start / 10)")
    p.add_argument("--sigma-v", type=float, help="start of σv (default: the log's noise scale)")
    p.add_argument("--sigma-f", type=float, help="start of σf (default: σv's start)")
    add_filter_arguments(p)
    p.add_argument(
        "--max-evals",
        type=int,
        default=DEFAULT_EVALUATIONS,
        help=f"most filter passes (default {DEFAULT_EVALUATIONS}, at most {MAX_EVALUATIONS})",
    )
    p.add_argument(
        "--fraction",
        type=float,
        default=DEFAULT_FIT_FRACTION,
        help="share of the log the held-out check fits on (default 0.7)",
    )
    p.set_defaults(handler=run_command)


def run_command(args: argparse.Namespace) -> int:
    """``mapwise tune``: the JSON document on stdout."""
    if not 1 <= args.max_evals <= MAX_EVALUATIONS:
        raise UsageError(f"--max-evals must be in [1, {MAX_EVALUATIONS}], got {args.max_evals}")
    if not 0.0 < args.fraction < 1.0:
        raise UsageError(f"--fraction must be in (0, 1), got {args.fraction:g}")
    if args.estimator in EKF_PARAMETERS:
        document = tune_ekf_command(args)
        print(json.dumps(_finite(document)))
        return 0
    wrong = [
        f for f in ("scenario", "seed", "duration", *EKF_STARTS) if getattr(args, f) is not None
    ]
    if wrong:
        flag = "--" + wrong[0].replace("_", "-")
        raise UsageError(f"{flag} applies to the EKF estimators, not --estimator {args.estimator}")
    if args.input is None or not args.axis or args.y is None:
        raise UsageError("a map filter needs a CSV log, --axis and --y")
    axes = [parse_axis(a) for a in args.axis]
    options: dict[str, Any] = {
        key: getattr(args, key)
        for key in ("p0", "theta0", "limit", "forgetting", "mu")
        if getattr(args, key) is not None
    }
    start = {
        key: getattr(args, key)
        for key in ("sigma_w", "sigma_v", "sigma_f")
        if getattr(args, key) is not None
    }
    sensor = _sensor(args)
    if sensor is not None:
        options["sensor"] = sensor
    request = AdaptRequest(
        input=args.input,
        estimator=args.estimator,
        axes=axes,
        output=args.y,
        options=options,
        locked=parse_cells(args.lock, len(axes)) if args.lock else [],
        time_column=args.time,
    )
    document = tune_log(request, start, max_evaluations=args.max_evals, fraction=args.fraction)
    print(json.dumps(_finite(document)))
    return 0


def _finite(value: Any) -> Any:
    """``value`` with every non-finite float replaced by ``None`` (JSON has no NaN)."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _sensor(args: argparse.Namespace) -> dict[str, Any] | None:
    """The sensor model of ``--lag``/``--delay-*`` (σf is tuned, so its value is a start)."""
    given = [args.delay_s, args.delay_samples, args.sigma_f]
    if args.lag is None:
        if any(v is not None for v in given):
            raise UsageError("sensor dynamics need --lag A (with --delay-s or --delay-samples)")
        return None
    sensor: dict[str, Any] = {"lag": args.lag, "delay_s": args.delay_s}
    if args.delay_samples is not None:
        sensor["delay_samples"] = args.delay_samples
    return sensor


def _data_rows(path: Path) -> int | None:
    """Lines after the header, counted before parsing so an oversized log is refused
    cheaply (``None`` if the file cannot be read: the CSV reader reports that)."""
    try:
        with path.open("rb") as f:
            lines = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 20), b""))
    except OSError:
        return None
    return max(lines - 1, 0)


def tune_log(
    request: AdaptRequest,
    start: dict[str, float],
    *,
    max_evaluations: int,
    fraction: float,
) -> dict[str, Any]:
    """Load the log, tune the filter's noise settings and check them on held-out data."""
    from app.io.csv_files import read_csv

    rows = _data_rows(request.input)
    if rows is not None and rows > MAX_SAMPLES:
        raise UsageError(f"{request.input}: {rows} rows; tune takes at most {MAX_SAMPLES} samples")
    columns = [name for name, _ in request.axes] + [request.output]
    t0 = time.perf_counter()
    log = read_csv(request.input, columns=columns, time_column=request.time_column)
    load_s = time.perf_counter() - t0
    sensor = request.options.get("sensor")
    if sensor and sensor.get("delay_s") and log.time_column is None:
        raise UsageError("--delay-s needs a time column in seconds: pass --time COLUMN")
    if len(log.signals) > MAX_SAMPLES:
        raise UsageError(
            f"{request.input}: {len(log.signals)} samples; tune takes at most {MAX_SAMPLES}"
        )
    config = build_config(request, log.signals.units)
    t0 = time.perf_counter()
    result = tune(
        request.estimator, config, log.signals, start=start, max_evaluations=max_evaluations
    )
    tune_s = time.perf_counter() - t0
    holdout = holdout_error(request.estimator, result.config, log.signals, fraction=fraction)
    return {
        **result.to_dict(),
        "unit": config["output_unit"],
        "holdout": holdout.to_dict(),
        "timing": {"load_s": load_s, "tune_s": tune_s},
    }


def tune_ekf_command(args: argparse.Namespace) -> dict[str, Any]:
    """``mapwise tune`` of a joint EKF: its log and config, the tuning, the held-out check."""
    from estimation.holdout_ekf import ekf_holdout

    wrong = [f for f in MAP_ONLY if getattr(args, f, None) not in (None, [])]
    if wrong:
        flag = "--" + wrong[0].replace("_", "-")
        raise UsageError(f"{flag} does not apply to --estimator {args.estimator}")
    if (args.input is None) == (args.scenario is None):
        raise UsageError("an EKF tunes on a CSV log or on --scenario NAME, one of the two")
    if args.scenario is None and (args.seed is not None or args.duration is not None):
        raise UsageError("--seed and --duration go with --scenario")
    start = {k: getattr(args, k) for k in EKF_STARTS if getattr(args, k) is not None}
    t0 = time.perf_counter()
    signals, config = _ekf_log(args)
    load_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = tune_ekf(args.estimator, config, signals, start=start, max_evaluations=args.max_evals)
    tune_s = time.perf_counter() - t0
    holdout = ekf_holdout(args.estimator, result.config, signals, fraction=args.fraction)
    return {
        **result.to_dict(),
        "unit": "kg/s",
        "holdout": holdout.to_dict(),
        "timing": {"load_s": load_s, "tune_s": tune_s},
    }


def _ekf_log(args: argparse.Namespace) -> tuple[Signals, dict[str, Any]]:
    """The EKF's log and config: the scenario's realisation (nominal mismatch) with the config
    drawn for it, or the CSV log's default channels with the default config."""
    if args.scenario is not None:
        from estimation.scenarios import get_scenario

        scenario = get_scenario(args.scenario)
        seed = 0 if args.seed is None else args.seed
        data = scenario.build(seed=seed, duration_s=args.duration)
        return data.signals, scenario.default_config(args.estimator, data)
    from app.io.csv_files import read_csv
    from estimation.observers.ekf_config import EkfChannels

    rows = _data_rows(args.input)
    if rows is not None and rows > MAX_SAMPLES:
        raise UsageError(f"{args.input}: {rows} rows; tune takes at most {MAX_SAMPLES} samples")
    channels = EkfChannels()
    log = read_csv(args.input, columns=[*channels.inputs(), channels.maf], time_column=args.time)
    return log.signals, {}
