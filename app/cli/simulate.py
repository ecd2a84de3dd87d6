"""``mapwise simulate``: a scenario's measured signals (CSV), its truth (JSON) and a plot, or
the scenario catalog (``--list``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from app.cli.errors import UsageError
from app.cli.run import add_mismatch_arguments
from estimation.scenarios import get_scenario, scenarios


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="write a scenario's measured signals (CSV) and truth (JSON)",
        description="Simulate a named scenario: measured signals to CSV (header 'name [unit]'), "
        "the truth (true maps with axes, true series) to JSON.",
    )
    p.add_argument("--list", action="store_true", help="print the scenario catalog and exit")
    p.add_argument("--scenario", help=f"scenario name: {', '.join(scenarios())}")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--duration", type=float, help="simulate only the first S seconds")
    add_mismatch_arguments(p)
    p.add_argument("--out", type=Path, metavar="FILE.csv", help="measured signals")
    p.add_argument("--truth", type=Path, metavar="T.json", help="the truth")
    p.add_argument("--plot", type=Path, metavar="OUT.html", help="a Plotly page of it all")
    p.add_argument("--json", action="store_true", help="with --list: the catalog as JSON")
    p.set_defaults(handler=run_command)


def run_command(args: argparse.Namespace) -> int:
    """``mapwise simulate``: write the files asked for and name them on stdout."""
    if args.list:
        print_catalog(as_json=args.json)
        return 0
    if not args.scenario:
        raise UsageError("--scenario NAME is required (or --list)")
    if args.out is None and args.plot is None:
        raise UsageError("--out FILE.csv (or --plot OUT.html) is required")
    from app.io.csv_files import write_csv

    data = get_scenario(args.scenario).build(
        seed=args.seed,
        duration_s=args.duration,
        mismatch=args.mismatch,
        averaging=args.averaging,
        noise_scale=args.noise_scale,
        transient_24s=args.transient_24s,
    )
    written = []
    try:
        if args.out is not None:
            write_csv(data.signals, args.out)
            written.append(str(args.out))
        if args.truth is not None:
            truth = {
                "scenario": data.scenario,
                "seed": data.seed,
                **data.truth,
                "metadata": data.metadata,
            }
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


def print_catalog(*, as_json: bool) -> None:
    """Every scenario: name, rate, duration, suggested estimators and description."""
    catalog = [s.catalog_entry() for s in scenarios().values()]
    if as_json:
        print(json.dumps(catalog, indent=1))
        return
    for entry in catalog:
        print(
            f"{entry['name']:<12} {entry['rate_hz']:>6g} Hz {entry['duration_s']:>7g} s  "
            f"[{', '.join(entry['suggested_estimators'])}]"
        )
        print(f"{'':<12} {entry['description']}")
