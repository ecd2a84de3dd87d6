"""``mapwise tune``: choose a map filter's noise settings from a log that has no truth.

It reads the same CSV log and flags as ``mapwise adapt`` and prints one JSON document
(docs/tuning.md, docs/cli.md)::

    {"estimator", "samples", "parameters": {"sigma_w", "sigma_v"[, "sigma_f"]},
     "start", "log_likelihood", "evaluations", "max_evaluations", "at_bound",
     "innovation": {"samples", "mean_nis", "mean_nis_band", "consistent", "in_band",
                    "innovation_mean", "innovation_rms", "log_likelihood"},
     "holdout": {"unit", "fraction", "fit_samples", "holdout_samples", "scored",
                 "adapted": {"rmse", "mae", "max_abs_error"}, "base": {…}, "innovations"},
     "unit", "timing": {"load_s", "tune_s"}}

``parameters`` are standard deviations in the output's unit; the search and its bounds are
those of :mod:`estimation.tuning`.
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
from estimation.tuning import DEFAULT_EVALUATIONS, MAX_EVALUATIONS, MAX_SAMPLES, tune


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune",
        help="choose σw, σv (σf) of a map filter by maximum innovation likelihood on a log",
        description="Choose a map filter's noise settings from a CSV log (no truth needed) by "
        "maximising the innovation log-likelihood; prints a JSON document. --sigma-* give the "
        f"search's starting point. At most {MAX_SAMPLES} samples and {MAX_EVALUATIONS} "
        "evaluations.",
    )
    p.add_argument("input", type=Path, help="CSV log with a header row")
    p.add_argument("--estimator", required=True, choices=names(EstimatorKind.MAP_FILTER))
    p.add_argument(
        "--axis",
        action="append",
        required=True,
        metavar="NAME=B1,B2,...",
        help="one per table dimension; NAME is an input column",
    )
    p.add_argument("--y", required=True, metavar="COLUMN", help="the measured table output")
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
