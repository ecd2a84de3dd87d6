"""Secrets never reach the logs: the WebSocket token travels in the query string (browsers
cannot set headers on a WebSocket), and uvicorn's access log writes query strings."""

from __future__ import annotations

import logging
import re

_SECRET = re.compile(r"((?:^|[?&])token=)[^&\s]*", re.IGNORECASE)


def redact(text: str) -> str:
    """``/api/runs/1/stream?token=mw_abc&x=1`` → ``/api/runs/1/stream?token=***&x=1``."""
    return _SECRET.sub(r"\1***", text)


class RedactTokens(logging.Filter):
    """Rewrites the path argument of uvicorn's access records (and any message text)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple) and record.args:
            record.args = tuple(redact(a) if isinstance(a, str) else a for a in record.args)
        elif isinstance(record.msg, str):
            record.msg = redact(record.msg)
        return True


_FILTER = RedactTokens()


def install_redaction() -> None:
    """Idempotent: on uvicorn's access and error loggers."""
    for name in ("uvicorn.access", "uvicorn.error"):
        logger = logging.getLogger(name)
        if _FILTER not in logger.filters:
            logger.addFilter(_FILTER)
