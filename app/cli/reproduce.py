"""``mapwise reproduce``: the papers' figures and tables beside ours, as one report.

The report itself is built by :mod:`app.reproduce`; this module is its command line.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="regenerate the report: the papers' figures and tables beside ours",
        description="Run the papers' cases live (SKF simulations 1-3, NOx, LPV, EKF Table 1, "
        "torque Tables III/IV/VI/VII, the Γ sensitivity of TQ (54)) and write DIR/report.md "
        "and DIR/report.html (one offline Plotly page). Exit code 1 if a section failed (the "
        "report is still written).",
    )
    p.add_argument(
        "--out", type=Path, default=Path("reproduce"), metavar="DIR", help="default ./reproduce"
    )
    p.add_argument("--seeds", default="0,1,2", metavar="S1,S2,...", help="default 0,1,2")
    p.add_argument(
        "--only",
        metavar="SECTIONS",
        help="comma-separated subset of skf,nox,lpv,ekf,torque,sensitivity",
    )
    p.add_argument(
        "--mismatch",
        choices=("none", "nominal", "severe"),
        default="nominal",
        help="plant/estimator model mismatch of every run (docs/fidelity.md; default nominal)",
    )
    p.set_defaults(handler=run_command)


def run_command(args: argparse.Namespace) -> int:
    """``mapwise reproduce``: progress on stderr, one line per section on stdout; exit code 1
    if a section failed."""
    from app.cli.run import MISMATCH
    from app.reproduce import SECTION_KEYS, parse_only, parse_seeds, reproduce

    seeds = parse_seeds(args.seeds)
    only = parse_only(args.only) if args.only is not None else SECTION_KEYS
    token = MISMATCH.set(args.mismatch)
    try:
        done = reproduce(
            args.out, seeds=seeds, only=only, progress=lambda line: print(line, file=sys.stderr)
        )
    finally:
        MISMATCH.reset(token)
    for section, seconds in done.sections:
        print(f"{section.key:<7} {seconds:6.1f} s  {section.verdict}")
    print(f"wrote {done.markdown} and {done.html} in {done.seconds:.1f} s")
    if done.failed:
        print(f"mapwise: sections failed: {', '.join(done.failed)}", file=sys.stderr)
        return 1
    return 0
