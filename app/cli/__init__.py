"""The ``mapwise`` command line: one module per subcommand, parsing and dispatch in
:mod:`app.cli.main`.

Every problem with the user's input ends the command with exit code 2 and exactly one line
on stderr that names the argument, column or line at fault.
"""

from app.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
