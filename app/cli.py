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

from app.cli_service import ServiceCliError
from app.errors import AppError
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
    p.add_argument(
        "--section",
        action="append",
        choices=["sweep", "nox", "filterpy", "sskf-gain", "simulators", "estimators", "observers"],
        help="run only this section (repeatable; default: all)",
    )
    p.set_defaults(handler=_cmd_bench)


def _cmd_bench(args: argparse.Namespace) -> int:
    from app.bench import format_report, run_benchmarks

    report = run_benchmarks(quick=args.quick, sections=args.section)
    print(json.dumps(report, indent=1) if args.json else format_report(report))
    return 0


def _run_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run an estimator on a simulated scenario and score it against the truth",
        description="Run any registered estimator on a named scenario and score it against the "
        "truth. --set key=value reaches any config key (dotted keys for sections, values as "
        "JSON), e.g. --set sigma_w=7 --set sensor.lag=0.9.",
    )
    p.add_argument("--scenario", required=True, help="scenario name (mapwise simulate --list)")
    p.add_argument("--estimator", required=True, help="estimator name")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--duration", type=float, help="simulate only the first S seconds")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--json", action="store_true", help="print the result document as JSON")
    p.set_defaults(handler=_cmd_run)


def _cmd_run(args: argparse.Namespace) -> int:
    from app.scenario_run import parse_set, run_scenario

    result = run_scenario(
        args.scenario,
        args.estimator,
        seed=args.seed,
        overrides=parse_set(args.set),
        duration_s=args.duration,
    )
    if args.json:
        print(json.dumps(result))
        return 0
    print(
        f"{result['estimator']} on {result['scenario']} (seed {result['seed']}), "
        f"{result['timing']['estimate_s']:.3f} s"
    )
    for key, value in result["metrics"].items():
        print(f"  {key:<22} {'n/a' if value is None else f'{value:.6g}'}")
    return 0


def _simulate_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="write a scenario's measured signals (CSV) and truth (JSON)",
        description="Simulate a named scenario: measured signals to CSV (header 'name [unit]'), "
        "the truth (true maps with axes, true series) to JSON.",
    )
    p.add_argument("--list", action="store_true", help="print the scenario catalog and exit")
    p.add_argument("--scenario", help="scenario name")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--duration", type=float, help="simulate only the first S seconds")
    p.add_argument("--out", type=Path, metavar="FILE.csv", help="measured signals")
    p.add_argument("--truth", type=Path, metavar="T.json", help="the truth")
    p.add_argument("--plot", type=Path, metavar="OUT.html", help="a Plotly page of it all")
    p.add_argument("--json", action="store_true", help="with --list: the catalog as JSON")
    p.set_defaults(handler=_cmd_simulate)


def _cmd_simulate(args: argparse.Namespace) -> int:
    from app.io.csv_files import write_csv
    from estimation.scenarios import get_scenario, scenarios

    if args.list:
        catalog = [s.catalog_entry() for s in scenarios().values()]
        if args.json:
            print(json.dumps(catalog, indent=1))
        else:
            for entry in catalog:
                print(
                    f"{entry['name']:<12} {entry['rate_hz']:>6g} Hz {entry['duration_s']:>7g} s  "
                    f"[{', '.join(entry['suggested_estimators'])}]"
                )
                print(f"{'':<12} {entry['description']}")
        return 0
    if not args.scenario:
        raise UsageError("--scenario NAME is required (or --list)")
    if args.out is None and args.plot is None:
        raise UsageError("--out FILE.csv (or --plot OUT.html) is required")
    data = get_scenario(args.scenario).build(seed=args.seed, duration_s=args.duration)
    written = []
    try:
        if args.out is not None:
            write_csv(data.signals, args.out)
            written.append(str(args.out))
        if args.truth is not None:
            truth = {"scenario": data.scenario, "seed": data.seed, **data.truth}
            if data.true_map is not None:
                truth["true_map"] = data.true_map.to_dict()
            args.truth.write_text(json.dumps(truth) + "\n")
            written.append(str(args.truth))
        if args.plot is not None:
            from app.plots import scenario_page

            scenario_page(data, args.plot)
            written.append(str(args.plot))
    except OSError as exc:
        raise UsageError(f"{exc.filename}: {exc.strerror}") from None
    print(f"{data.scenario}: {len(data.signals)} samples -> {', '.join(written)}")
    return 0


def _reproduce_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="regenerate the report: the papers' figures and tables beside ours",
        description="Run the papers' cases live (SKF simulations 1-3, NOx, LPV, EKF Table 1, "
        "torque Tables III/IV/VI/VII) and write DIR/report.md and DIR/report.html (one "
        "offline Plotly page). Exit code 1 if a section failed (the report is still written).",
    )
    p.add_argument(
        "--out", type=Path, default=Path("reproduce"), metavar="DIR", help="default ./reproduce"
    )
    p.add_argument("--seeds", default="0,1,2", metavar="S1,S2,...", help="default 0,1,2")
    p.add_argument(
        "--only", metavar="SECTIONS", help="comma-separated subset of skf,nox,lpv,ekf,torque"
    )
    p.set_defaults(handler=_cmd_reproduce)


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from app.reproduce import SECTION_KEYS, parse_only, parse_seeds, reproduce

    seeds = parse_seeds(args.seeds)
    only = parse_only(args.only) if args.only is not None else SECTION_KEYS
    done = reproduce(
        args.out, seeds=seeds, only=only, progress=lambda line: print(line, file=sys.stderr)
    )
    for section, seconds in done.sections:
        print(f"{section.key:<7} {seconds:6.1f} s  {section.verdict}")
    print(f"wrote {done.markdown} and {done.html} in {done.seconds:.1f} s")
    if done.failed:
        print(f"mapwise: sections failed: {', '.join(done.failed)}", file=sys.stderr)
        return 1
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="mapwise", description=__doc__.splitlines()[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _adapt_parser(sub)
    _run_parser(sub)
    _simulate_parser(sub)
    _bench_parser(sub)
    _reproduce_parser(sub)
    from app.cli_service import add_parsers as _service_parsers
    from app.cli_sweep import add_parser as _sweep_parser

    _service_parsers(sub)
    _sweep_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return int(args.handler(args))
    except (UsageError, EstimationError, ServiceCliError, AppError) as exc:
        message = " ".join(str(exc).split())
        print(f"mapwise: error: {message}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
