"""One error hierarchy for the service (rendered as HTTP responses by app.api.errors).

Services raise :class:`AppError` subclasses (never ``HTTPException``); every error response,
including request validation, unknown routes and wrong methods, has the body
``{"error": {"code", "message", "field"}}``, rendered by :mod:`app.api.errors`. Nothing here
imports a web framework: the run workers import this module, and FastAPI would cost each
spawned worker a quarter of a second.
"""

from __future__ import annotations

from typing import Any


class AppError(Exception):
    """Base of every service error: a stable ``code``, an HTTP status and the field at fault."""

    code = "error"
    status = 500

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.field = field

    def body(self) -> dict[str, Any]:
        return {"error": {"code": self.code, "message": self.message, "field": self.field}}


class InvalidRequestError(AppError, ValueError):
    """The request is well-formed but its content is not acceptable."""

    code = "validation_error"
    status = 422


class MalformedRequestError(AppError, ValueError):
    """The request body cannot be read at all (malformed JSON, wrong multipart)."""

    code = "validation_error"
    status = 400


class NotFoundError(AppError, LookupError):
    code = "not_found"
    status = 404


class ConflictError(AppError):
    """The resource is in a state that forbids the operation."""

    code = "conflict"
    status = 409


class SupersededError(AppError):
    """A worker's attempt at a run is no longer the live one (a newer attempt claimed it):
    the worker stops without writing anything more."""

    code = "superseded"
    status = 409


class DatabaseUnavailableError(AppError):
    """The database cannot be reached or is restarting: retry shortly (503, Retry-After)."""

    code = "database_unavailable"
    status = 503


class PayloadTooLargeError(AppError):
    code = "payload_too_large"
    status = 413


class UnsupportedFormatError(AppError, ValueError):
    code = "unsupported_format"
    status = 415


class UnauthorizedError(AppError):
    code = "unauthorized"
    status = 401


class InsufficientScopeError(AppError):
    """The token is valid but lacks the scope the route needs (RFC 6750 §3.1)."""

    code = "insufficient_scope"
    status = 403

    def __init__(self, message: str, *, scope: str) -> None:
        super().__init__(message)
        self.scope = scope


class MethodNotAllowedError(AppError):
    code = "method_not_allowed"
    status = 405


def field_of(loc: tuple[Any, ...] | list[Any]) -> str | None:
    """``("body", "config", "sigma_w")`` → ``"config.sigma_w"``; list indices as ``[i]``."""
    parts: list[str] = []
    for p in loc:
        if p in ("body", "query", "path", "header", "cookie", "form") and not parts:
            continue
        if isinstance(p, int):
            parts.append(f"[{p}]")
        else:
            parts.append(("." if parts else "") + str(p))
    return "".join(parts) or None
