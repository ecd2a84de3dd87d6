"""The ``mapwise`` command line.

Every problem with the user's input ends the command with exit code 2 and exactly one line
on stderr that names the argument, column or line at fault.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from estimation.errors import EstimationError

EXIT_USAGE = 2


class UsageError(Exception):
    """Bad command-line input: reported as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def _adapt_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "adapt",
        help="learn a look-up table from a CSV log with a map-updating filter",
        description="Learn a look-up table from a CSV log. --sigma-* are standard deviations "
        "in the output's unit; --p0 is a variance.",
    )
    p.add_argument("input", type=Path, help="CSV log with a header row")
    p.add_argument("--estimator", required=True, choices=["kf", "skf", "sskf", "rls", "nlms"])
    p.add_argument(
        "--axis",
        action="append",
        required=True,
        metavar="NAME=B1,B2,...",
        help="one per table dimension; NAME is an input column",
    )
    p.add_argument("--y", required=True, metavar="COLUMN", help="the measured table output")
    p.add_argument("--sigma-w", type=float, help="random-walk σw per cell and sample")
    p.add_argument("--sigma-v", type=float, help="measurement noise σv")
    p.add_argument("--p0", type=float, help="initial variance of every cell")
    p.add_argument("--theta0", type=float, help="initial value of every cell")
    p.add_argument("--limit", choices=["none", "p0"], help="covariance limiting")
    p.add_argument("--lag", type=float, help="sensor lag pole a (0 ≤ a < 1)")
    p.add_argument("--delay-s", type=float, help="sensor delay in seconds (needs --time)")
    p.add_argument("--delay-samples", type=int, help="sensor delay in samples")
    p.add_argument("--sigma-f", type=float, help="process noise σf of the sensor state")
    p.add_argument("--time", metavar="COLUMN", help="time column in seconds")
    p.add_argument("--forgetting", type=float, help="RLS forgetting factor λ")
    p.add_argument("--mu", type=float, help="NLMS step size μ")
    p.add_argument("--lock", metavar="CELLS", help='locked cells, 0-based: "i,j;i,j"')
    p.add_argument("--gate-sigma", type=float, help="reject samples with |e| > K·sqrt(s)")
    p.add_argument("--out", type=Path, metavar="MAP.json", help="write the map document here")
    p.add_argument("--json", action="store_true", help="print the map document on stdout")
    p.set_defaults(handler=_cmd_adapt)


def _cmd_adapt(args: argparse.Namespace) -> int:
    from app.adapt import AdaptRequest, adapt, format_table, parse_axis, parse_cells

    axes = [parse_axis(a) for a in args.axis]
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
    request = AdaptRequest(
        input=args.input,
        estimator=args.estimator,
        axes=axes,
        output=args.y,
        options=options,
        locked=parse_cells(args.lock, len(axes)) if args.lock else [],
        gate_sigma=args.gate_sigma,
        time_column=args.time,
    )
    document = adapt(request)
    if args.out is not None:
        try:
            args.out.write_text(json.dumps(document, indent=1) + "\n")
        except OSError as exc:
            raise UsageError(f"--out {args.out}: {exc.strerror}") from None
    print(json.dumps(document) if args.json else format_table(document))
    return 0


def _bench_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help="measure samples/s of every filter (and FilterPy's KF for comparison)",
        description="Benchmarks the map filters on n×n tables (n = 2…21, the SKF paper's "
        "Fig. 5 sweep) and the 12×18 NOx table, and the full KF against FilterPy.",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("--quick", action="store_true", help="fewer sizes and samples (smoke run)")
    p.set_defaults(handler=_cmd_bench)


def _cmd_bench(args: argparse.Namespace) -> int:
    from app.bench import format_report, run_benchmarks

    report = run_benchmarks(quick=args.quick)
    print(json.dumps(report, indent=1) if args.json else format_report(report))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="mapwise", description=__doc__.splitlines()[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _adapt_parser(sub)
    _bench_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return int(args.handler(args))
    except (UsageError, EstimationError) as exc:
        message = " ".join(str(exc).split())
        print(f"mapwise: error: {message}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
