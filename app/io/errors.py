"""The one error type of file input/output: a bad upload, map file or gate definition.

Each error carries a machine-readable ``code``, the ``field`` it concerns (a column, a
channel, ``"file"``, ``"signals.y"``, ``"config.gates[0].channel"``…) and a one-line
message that names the line and column where that applies. The HTTP layer renders it as
``{"error": {"code", "message", "field"}}`` with :attr:`InputError.status`.
"""

from __future__ import annotations

from typing import Any

from app.errors import AppError

VALIDATION_ERROR = "validation_error"
UNSUPPORTED_FORMAT = "unsupported_format"
PAYLOAD_TOO_LARGE = "payload_too_large"

_STATUS = {VALIDATION_ERROR: 422, UNSUPPORTED_FORMAT: 415, PAYLOAD_TOO_LARGE: 413}


class InputError(AppError, ValueError):
    """Input that cannot be used as given; ``str(exc)`` is the message. Rendered by the
    service's one :class:`~app.errors.AppError` handler."""

    def __init__(
        self,
        message: str,
        *,
        field: str | None = None,
        code: str = VALIDATION_ERROR,
        line: int | None = None,
    ) -> None:
        if code not in _STATUS:
            raise ValueError(f"unknown error code {code!r}")
        super().__init__(message, field=field)
        self.code = code
        self.status = _STATUS[code]  # 422, 415 or 413
        self.line = line

    def to_dict(self) -> dict[str, Any]:
        return self.body()["error"]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.message!r}, field={self.field!r}, code={self.code!r})"


def unsupported(message: str, *, field: str | None = "file") -> InputError:
    return InputError(message, field=field, code=UNSUPPORTED_FORMAT)


def too_large(message: str, *, field: str | None = "file") -> InputError:
    return InputError(message, field=field, code=PAYLOAD_TOO_LARGE)
