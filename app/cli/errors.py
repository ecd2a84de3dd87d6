"""The command line's one error: bad input, reported as one line on stderr with exit code 2."""

from __future__ import annotations

EXIT_USAGE = 2


class UsageError(Exception):
    """Bad command-line input, settings or database: ``mapwise: error: ...``, exit code 2."""
