"""The one handler that renders every error as ``{"error": {"code", "message", "field"}}``:
the service's :class:`~app.errors.AppError`, request validation, unknown routes and wrong
methods (docs/rest-api.md#errors)."""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from app.errors import (
    AppError,
    DatabaseUnavailableError,
    InsufficientScopeError,
    InvalidRequestError,
    MalformedRequestError,
    MethodNotAllowedError,
    NotFoundError,
    UnauthorizedError,
    field_of,
)
from estimation.errors import EstimationError

log = logging.getLogger("mapwise")


def error_response(error: AppError) -> JSONResponse:
    headers = None
    if isinstance(error, UnauthorizedError):
        headers = {"WWW-Authenticate": "Bearer"}
    elif isinstance(error, InsufficientScopeError):
        headers = {"WWW-Authenticate": f'Bearer error="insufficient_scope", scope="{error.scope}"'}
    elif isinstance(error, DatabaseUnavailableError):
        headers = {"Retry-After": "2"}
    return JSONResponse(error.body(), status_code=error.status, headers=headers)


_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def allowed_methods(request: Request) -> list[str]:
    """Every method some route serves at the request's path.

    Starlette's 405 names only the methods of the first route whose path matched, while
    ``GET /x/{id}`` and ``DELETE /x/{id}`` are two routes: each method is asked of every
    route instead (``BaseRoute.matches`` with a scope of that method).
    """
    allowed = []
    for method in _METHODS:
        scope = {
            "type": "http",
            "method": method,
            "path": request.scope["path"],
            "root_path": request.scope.get("root_path", ""),
            "headers": [],
        }
        if any(route.matches(scope)[0] == Match.FULL for route in request.app.router.routes):
            allowed.append(method)
    return allowed


def install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(AppError)
    async def _app_error(_: Request, exc: AppError) -> JSONResponse:
        return error_response(exc)

    @app.exception_handler(RequestValidationError)
    async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        errors = exc.errors()
        first = errors[0] if errors else {"loc": (), "msg": "invalid request"}
        if first.get("type") == "json_invalid":
            detail = (first.get("ctx") or {}).get("error", "")
            return error_response(
                MalformedRequestError(f"the request body is not valid JSON {detail}".strip())
            )
        if first.get("type") == "model_attributes_type" and tuple(first.get("loc", ())) == (
            "body",
        ):
            return error_response(MalformedRequestError("the request body must be a JSON object"))
        message = "; ".join(
            f"{field_of(e.get('loc', ())) or 'body'}: {e.get('msg', 'invalid')}" for e in errors
        )
        return error_response(InvalidRequestError(message, field=field_of(first.get("loc", ()))))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        error: AppError
        headers = dict(exc.headers or {})
        if exc.status_code == 404:
            error = NotFoundError(str(exc.detail) if exc.detail != "Not Found" else "no such route")
        elif exc.status_code == 405:
            allowed = allowed_methods(request)
            if allowed and request.method not in allowed:
                headers["Allow"] = ", ".join(allowed)
            error = MethodNotAllowedError(
                f"{request.method} is not allowed on this route; allowed: {headers['Allow']}"
                if headers.get("Allow")
                else "method not allowed on this route"
            )
        else:
            error = AppError(str(exc.detail))
            error.status = exc.status_code
            error.code = "http_error"
        response = error_response(error)
        response.headers.update(headers)
        return response

    @app.exception_handler(EstimationError)
    async def _estimation(_: Request, exc: EstimationError) -> JSONResponse:
        return error_response(InvalidRequestError(" ".join(str(exc).split())))

    @app.exception_handler(Exception)
    async def _internal(_: Request, exc: Exception) -> JSONResponse:
        log.exception("unhandled error", exc_info=exc)
        error = AppError("internal error; see the server log")
        error.code = "internal_error"
        return error_response(error)
