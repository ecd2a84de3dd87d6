"""``mapwise reproduce``: the papers' figures and tables beside ours, as one report.

The report itself is built by :mod:`app.reproduce`; this module is its command line. The
default seeds are the held-out ones, 100–109 (:mod:`app.reproduce.seeds`). The tuning rules'
sensitivity tables (section ``sensitivity``: Γ of TQ (54), γ of the LPV observer) are also
printed on stdout. ``--robustness`` adds the robustness study
(:mod:`app.reproduce.robustness`: every headline figure against mismatch and noise level in
five cells, about 1 min of CPU per seed; it is not in the default run) and prints its table;
``--robustness-duration S`` cuts its scenarios to their first S seconds; ``--plots DIR``
also writes its plot to ``DIR/robustness.html`` (Plotly, offline; matplotlib is not a
dependency).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from app.reproduce import Reproduced


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="regenerate the report: the papers' figures and tables beside ours",
        description="Run the papers' cases live (SKF simulations 1-3, NOx, LPV, EKF Table 1, "
        "torque Tables III/IV/VI/VII, the tuning rules' sensitivity tables (Γ of TQ (54), γ of "
        "the LPV observer); with --robustness the "
        "robustness study) and write DIR/report.md, DIR/report.html (one offline Plotly page) "
        "and DIR/report.json. Exit code 1 if a section failed (the report is still written).",
    )
    p.add_argument(
        "--out", type=Path, default=Path("reproduce"), metavar="DIR", help="default ./reproduce"
    )
    p.add_argument(
        "--seeds",
        default="100-109",
        metavar="S1,S2,A-B,...",
        help="seeds and ranges; default 100-109, the held-out seeds nothing was tuned on "
        "(0-4 are the tuning seeds; the report labels each seed)",
    )
    p.add_argument(
        "--only",
        metavar="SECTIONS",
        help="comma-separated subset of skf,nox,lpv,ekf,torque,sensitivity,robustness",
    )
    p.add_argument(
        "--robustness",
        action="store_true",
        help="add the robustness study: every headline figure at mismatch none/nominal/severe "
        "and noise × 0.5/1/2 (about 1 min of CPU per seed; printed as a table)",
    )
    p.add_argument(
        "--robustness-parts",
        metavar="PARTS",
        help="with the study: comma-separated subset of lpv,lpv-literal,ekf,ekf-literal,nox,"
        "torque (default all; nox,torque take seconds, lpv and ekf most of the time)",
    )
    p.add_argument(
        "--robustness-duration",
        type=_seconds,
        metavar="S",
        help="with the study: cut every scenario to its first S seconds (a quick look; the "
        "papers' segments are cut with it; default: whole records)",
    )
    p.add_argument(
        "--plots",
        type=Path,
        metavar="DIR",
        help="also write the robustness plot to DIR/robustness.html (with the study only)",
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
    from app.reproduce import parse_only, parse_seeds, reproduce
    from app.reproduce.fidelity import DURATION_S
    from app.reproduce.robustness import SELECTED_PARTS, parse_parts
    from app.reproduce.runner import DEFAULT_KEYS, SECTION_KEYS

    seeds = parse_seeds(args.seeds)
    only = parse_only(args.only) if args.only is not None else DEFAULT_KEYS
    if args.robustness:
        only = tuple(k for k in SECTION_KEYS if k in only or k == "robustness")

    if args.robustness_duration is not None and "robustness" not in only:
        print("mapwise: --robustness-duration: no robustness study in this run", file=sys.stderr)
    token = MISMATCH.set(args.mismatch)
    parts = SELECTED_PARTS.set(parse_parts(args.robustness_parts))
    duration = DURATION_S.set(args.robustness_duration)
    try:
        done = reproduce(
            args.out, seeds=seeds, only=only, progress=lambda line: print(line, file=sys.stderr)
        )
    finally:
        DURATION_S.reset(duration)
        SELECTED_PARTS.reset(parts)
        MISMATCH.reset(token)
    for section, seconds in done.sections:
        print(f"{section.key:<7} {seconds:6.1f} s  {section.verdict}")
    _print_tables(done, "sensitivity")
    _robustness_outputs(done, args.plots)
    print(f"wrote {done.markdown}, {done.html} and {done.json} in {done.seconds:.1f} s")
    if done.failed:
        print(f"mapwise: sections failed: {', '.join(done.failed)}", file=sys.stderr)
        return 1
    return 0


def _seconds(text: str) -> float:
    """``--robustness-duration``: a number of seconds, at least 1."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value >= 1.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected seconds >= 1, got {text!r}")
    return value


def _print_tables(done: Reproduced, key: str) -> None:
    """Every table of section ``key`` on stdout, as Markdown (nothing if it did not run)."""
    from app.reproduce.report import Table, table_markdown

    for section, _ in done.sections:
        if section.key == key:
            for block in section.blocks:
                if isinstance(block, Table):
                    print(table_markdown(block))


def _robustness_outputs(done: Reproduced, plots: Path | None) -> None:
    """The robustness table on stdout and, with ``plots``, its figure as an HTML page."""
    from html import escape

    from app.cli.errors import UsageError
    from app.plots import offline_page
    from app.reproduce.report import Figure

    sections = [s for s, _ in done.sections if s.key == "robustness"]
    if not sections:
        if plots is not None:
            print("mapwise: --plots: no robustness study in this run, no plot", file=sys.stderr)
        return
    blocks = sections[0].blocks
    _print_tables(done, "robustness")
    figures = [b for b in blocks if isinstance(b, Figure)]
    if plots is None or not figures:
        return
    try:
        plots.mkdir(parents=True, exist_ok=True)
        path = plots / "robustness.html"
        offline_page(
            "mapwise robustness study",
            [f"<p>{escape(figures[0].caption)}</p>", figures[0].figure],
            path,
        )
    except OSError as exc:
        raise UsageError(f"--plots {plots}: {exc.strerror or exc}") from None
    print(f"wrote {path}")
