"""``mapwise adapt``: learn a look-up table from a logged drive with one map filter.

It prints (``--json``) or writes (``--out``) the map document of :mod:`app.io.map_json`, a
contract used by scripts outside the repository.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.cli import adapt_a2l
from app.cli.errors import UsageError
from app.io.map_json import map_document
from estimation.errors import ConfigError
from estimation.registry import EstimatorKind, get_spec, names

if TYPE_CHECKING:
    from app.io.csv_files import CsvLog
    from estimation.estimator import Estimator
    from estimation.signals import Signals
    from estimation.table import Table

#: Samples of the warm-up fit (:func:`warm_up`): enough to run every kernel once.
WARMUP_SAMPLES = 4096

# The option flags and the config key each sets; a filter takes those its config model has,
# and any other is a usage error, not silently ignored.
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


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "adapt",
        help="learn a look-up table from a CSV log with a map-updating filter",
        description="Learn a look-up table from a CSV log. --sigma-* are standard deviations "
        "in the output's unit; --p0 is a variance.",
    )
    p.add_argument("input", type=Path, help="CSV log with a header row")
    p.add_argument("--estimator", required=True, choices=names(EstimatorKind.MAP_FILTER))
    p.add_argument(
        "--axis",
        action="append",
        metavar="NAME=B1,B2,...",
        help="one per table dimension; NAME is an input column (with --a2l: optional)",
    )
    p.add_argument(
        "--y",
        metavar="COLUMN",
        help="the measured table output (with --a2l: optional if a channel is named as the map)",
    )
    p.add_argument("--sigma-w", type=float, help="random-walk σw per cell and sample")
    p.add_argument("--sigma-v", type=float, help="measurement noise σv")
    p.add_argument("--sigma-f", type=float, help="process noise σf of the sensor state")
    add_filter_arguments(p)
    p.add_argument("--gate-sigma", type=float, help="reject samples with |e| > K·sqrt(s)")
    p.add_argument("--out", type=Path, metavar="MAP.json", help="write the map document here")
    p.add_argument("--json", action="store_true", help="print the map document on stdout")
    adapt_a2l.add_arguments(p)
    p.set_defaults(handler=run_command)


def add_filter_arguments(p: argparse.ArgumentParser) -> None:
    """The map filter's options other than its noise levels, shared by ``adapt`` and ``tune``:
    initial state, covariance limiting, sensor lag/delay, time column, RLS/NLMS steps, locks.
    """
    p.add_argument("--p0", type=float, help="initial variance of every cell")
    p.add_argument("--theta0", type=float, help="initial value of every cell")
    p.add_argument("--limit", choices=["none", "p0"], help="covariance limiting")
    p.add_argument("--lag", type=float, help="sensor lag pole a (0 ≤ a < 1)")
    p.add_argument("--delay-s", type=float, help="sensor delay in seconds (needs --time)")
    p.add_argument("--delay-samples", type=int, help="sensor delay in samples")
    p.add_argument("--time", metavar="COLUMN", help="time column in seconds")
    p.add_argument("--forgetting", type=float, help="RLS forgetting factor λ")
    p.add_argument("--mu", type=float, help="NLMS step size μ")
    p.add_argument("--lock", metavar="CELLS", help='locked cells, 0-based: "i,j;i,j"')


def run_command(args: argparse.Namespace) -> int:
    """``mapwise adapt``: the map document to ``--out``, then the table (or JSON) on stdout."""
    adapt_a2l.check_flags(args)
    if args.a2l is None:
        missing = [flag for flag, v in (("--axis", args.axis), ("--y", args.y)) if v is None]
        if missing:
            raise UsageError(f"the following arguments are required: {', '.join(missing)}")
    axes = [parse_axis(a) for a in args.axis or []]
    options: dict[str, Any] = {
        key: getattr(args, key)
        for key in ("sigma_w", "sigma_v", "p0", "theta0", "limit", "forgetting", "mu")
        if getattr(args, key) is not None
    }
    sensor_flags = {
        "lag": args.lag,
        "delay_s": args.delay_s,
        "delay_samples": args.delay_samples,
        "sigma_f": args.sigma_f,
    }
    if any(v is not None for v in sensor_flags.values()):
        if args.lag is None:
            raise UsageError("sensor dynamics need --lag A (with --delay-s or --delay-samples)")
        sensor = {k: v for k, v in sensor_flags.items() if v is not None}
        sensor.setdefault("delay_s", None)
        options["sensor"] = sensor
    log = target = None
    load_s = 0.0
    if args.a2l is not None:  # every numeric column: the A2L's quantities are matched to them
        t0 = time.perf_counter()
        log = load_log(args.input, None, args.time)
        load_s = time.perf_counter() - t0
        target = adapt_a2l.resolve(args, log.signals.names, axes or None)
        axes = target.axes
        start = adapt_a2l.theta0(target)
        if start is not None and "theta0" not in options:
            allowed = get_spec(args.estimator).config_model.model_fields
            if "theta0" in allowed:
                options["theta0"] = start
    request = AdaptRequest(
        input=args.input,
        estimator=args.estimator,
        axes=axes,
        output=args.y if target is None else target.output,
        options=options,
        locked=parse_cells(args.lock, len(axes)) if args.lock else [],
        gate_sigma=args.gate_sigma,
        time_column=args.time,
    )
    document = adapt(request, log=log, load_s=load_s)
    if target is not None:
        document |= adapt_a2l.write_outputs(args, target, document_table(document))
    if args.out is not None:
        try:
            args.out.write_text(json.dumps(document, indent=1) + "\n")
        except OSError as exc:
            raise UsageError(f"--out {args.out}: {exc.strerror}") from None
    print(json.dumps(document) if args.json else format_table(document))
    return 0


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
    allowed = set(_FLAGS) & set(get_spec(request.estimator).config_model.model_fields)
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


def load_log(path: Path, columns: list[str] | None, time_column: str | None) -> CsvLog:
    """The CSV log's ``columns`` (``None``: every numeric column)."""
    from app.io.csv_files import read_csv

    return read_csv(path, columns=columns, time_column=time_column)


def document_table(document: dict[str, Any]) -> Table:
    """The learned table of a map document."""
    from estimation.table import Axis, Table

    axes = [Axis(a["name"], a.get("unit", ""), a["breakpoints"]) for a in document["axes"]]
    return Table(axes, np.asarray(document["values"], dtype=np.float64))


def adapt(
    request: AdaptRequest, *, log: CsvLog | None = None, load_s: float = 0.0
) -> dict[str, Any]:
    """Load the log (unless given, read in ``load_s``), run the filter over it and return
    the contract document."""
    spec = get_spec(request.estimator)
    map_filters = names(EstimatorKind.MAP_FILTER)
    if request.estimator not in map_filters:
        raise ConfigError(f"--estimator must be one of {', '.join(map_filters)}")
    columns = [name for name, _ in request.axes] + [request.output]
    if log is None:
        t0 = time.perf_counter()
        log = load_log(request.input, columns, request.time_column)
        load_s = time.perf_counter() - t0
    sensor = request.options.get("sensor")
    if sensor and sensor.get("delay_s") and log.time_column is None:
        raise ConfigError("--delay-s needs a time column in seconds: pass --time COLUMN")
    estimator = spec.build(build_config(request, log.signals.units))
    t0 = time.perf_counter()
    warm_up(estimator, log.signals)
    warmup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    final = estimator.fit(log.signals)
    estimate_s = time.perf_counter() - t0
    return map_document(
        final,
        samples=len(log.signals),
        load_s=load_s,
        estimate_s=estimate_s,
        warmup_s=warmup_s,
        quantity=request.output,
        unit=log.signals.units.get(request.output, ""),
    )


def warm_up(estimator: Estimator, signals: Signals) -> None:
    """Fit the log's first :data:`WARMUP_SAMPLES` samples once, so that numba's one-off start
    in a new process (loading its cached kernels, 1–2 s) is ``timing.warmup_s`` and
    ``timing.estimate_s`` times the estimate alone."""
    with contextlib.suppress(ConfigError):  # a sensor delay longer than the slice
        estimator.fit(signals.slice(0, min(len(signals), WARMUP_SAMPLES)))


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
