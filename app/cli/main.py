"""The ``mapwise`` command line.

The argument parser and the dispatch; each subcommand's flags and handler live in its own
module of :mod:`app.cli`. Every problem with the user's input ends the command with exit
code 2 and exactly one line on stderr that names the argument, column or line at fault.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

from app.cli import a2l, adapt, bench, reproduce, run, serve, simulate, sweep, tune
from app.cli.errors import EXIT_USAGE, UsageError
from app.errors import AppError
from estimation.errors import EstimationError

__all__ = ["EXIT_USAGE", "UsageError", "build_parser", "main"]


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    """The ``mapwise`` parser: every subcommand, its handler under ``handler``."""
    parser = _Parser(prog="mapwise", description=__doc__.splitlines()[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    adapt.add_parser(sub)
    a2l.add_parser(sub)
    run.add_parser(sub)
    simulate.add_parser(sub)
    bench.add_parser(sub)
    reproduce.add_parser(sub)
    serve.add_parsers(sub)
    sweep.add_parser(sub)
    tune.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``mapwise`` with ``argv`` (default ``sys.argv[1:]``); return the exit code."""
    try:
        args = build_parser().parse_args(argv)
        return int(args.handler(args))
    except (UsageError, EstimationError, AppError) as exc:
        message = " ".join(str(exc).split())
        print(f"mapwise: error: {message}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
