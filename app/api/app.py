"""The app factory: ``create_app(settings)``.

Start-up checks the database schema (an empty database gets the schema; an out-of-date one
is refused, naming ``mapwise db upgrade``), starts the run executor (whose sweep marks runs
left ``running`` as ``interrupted``) and the live hub. The event loop only moves bytes:
endpoints touching the database or the numerics are plain functions run in the thread pool.

Outermost first, a request meets: the security headers (CSP and friends), the Host
allowlist (:mod:`app.api.security`), the body limit, strict JSON, CORS, then the routes,
each ``/api`` route behind a token with the route's scope (:mod:`app.api.deps`).
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import Depends, FastAPI
from fastapi.middleware.cors import CORSMiddleware
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.api.deps import Services, require_token
from app.api.errors import install_error_handlers
from app.api.routers import (
    base_maps,
    catalog,
    datasets,
    ecus,
    frontend,
    me,
    runs,
    stream,
    sweeps,
)
from app.api.security import DEFAULT_CSP, TrustedHosts, docs_router
from app.config import Settings, get_settings
from app.db.engine import Database
from app.db.migrate import check_schema, migrate
from app.errors import AppError, InvalidRequestError, PayloadTooLargeError
from app.logs import install_redaction
from app.runs.executor import RunExecutor, make_executor
from app.runs.hub import LiveHub
from app.services.base_maps import BaseMapService
from app.services.datasets import DatasetService
from app.services.ecus import EcuService
from app.services.run_exports import RunExports
from app.services.runs import RunService
from app.services.sweeps import SweepService
from app.services.tokens import TokenService
from app.store import open_store

MULTIPART_OVERHEAD = 1 << 20  # form fields and boundaries around the file


class SchemaError(RuntimeError):
    """The database schema is not the one this code needs."""


def prepare_database(settings: Settings) -> str:
    """Create the schema on an empty database; refuse an out-of-date or unknown one."""
    check = check_schema(settings.database_url)
    if check.state != "current":  # migrated if empty; else checked again under the lock
        _, check = migrate(settings.database_url, store_url=settings.store_url, only_if_empty=True)
    if check.state != "current":
        raise SchemaError(check.message)
    return check.head


def create_app(settings: Settings | None = None, *, execute_runs: bool = True) -> FastAPI:
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        install_redaction()
        revision = await asyncio.to_thread(prepare_database, settings)
        db = Database(settings.database_url)
        hub = LiveHub(
            max_per_run=settings.max_viewers_per_run,
            max_per_client=settings.max_viewers_per_client,
            max_total=settings.max_viewers,
        )
        executor = make_executor(settings, db, hub) if execute_runs else None
        run_service = RunService(db, settings, executor)
        app.state.services = Services(
            settings=settings,
            db=db,
            hub=hub,
            executor=executor,
            datasets=DatasetService(
                db,
                open_store(settings.store_url),
                in_child=True,
                memory_mb=settings.run_memory_mb,
            ),
            runs=run_service,
            exports=RunExports(db, settings),
            sweeps=SweepService(db, run_service),
            base_maps=BaseMapService(db, max_cells=settings.max_cells),
            tokens=TokenService(db),
            ecus=EcuService(db, settings),
            revision=revision,
        )
        if isinstance(executor, RunExecutor):
            # In the loop's own thread: the workers' parent-death signal is tied to the
            # thread that spawns them, and this one lives as long as the server.
            executor.start(asyncio.get_running_loop())
        elif executor is not None:  # connecting to a scheduler blocks: not on the loop
            await asyncio.to_thread(executor.start, asyncio.get_running_loop())
        # Everything loaded so far (FastAPI, pydantic, SQLAlchemy, numpy: hundreds of
        # thousands of objects) lives as long as the server: out of the collector's sight, a
        # full collection scans only what requests create, a few ms instead of 100-200 ms
        # of event loop stalled (a burst of a thousand WebSocket handshakes triggers them).
        gc.collect()
        gc.freeze()
        app.state.services.loop_lag.start()
        revocations = asyncio.create_task(
            stream.watch_revocations(app.state.services), name="mapwise-revocations"
        )
        try:
            yield
        finally:
            revocations.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await revocations
            await app.state.services.loop_lag.stop()
            if executor is not None:
                await asyncio.to_thread(executor.shutdown)
            await asyncio.to_thread(app.state.services.datasets.close)
            db.dispose()

    app = FastAPI(
        title="mapwise",
        summary="Online adaptation of engine look-up tables: runs, live maps, exports.",
        version=_version(),
        lifespan=lifespan,
        # Served by docs_router instead, behind the same token as the API.
        openapi_url=None,
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    install_error_handlers(app)
    api = [Depends(require_token)]
    app.include_router(catalog.open_router, prefix="/api")
    app.include_router(docs_router(app))
    for module in (catalog, me, datasets, runs, base_maps, sweeps, ecus):
        app.include_router(module.router, prefix="/api", dependencies=api)
    app.include_router(stream.router, prefix="/api")
    app.include_router(frontend.router)
    static = frontend.static_files()
    if static is not None:
        app.mount("/static", static, name="static")
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "PUT", "PATCH", "DELETE"],
            allow_headers=["Authorization", "Content-Type"],
        )
    app.add_middleware(StrictJson, max_bytes=settings.max_json_bytes)
    app.add_middleware(BodyLimit, max_bytes=settings.max_upload_bytes + MULTIPART_OVERHEAD)
    app.add_middleware(TrustedHosts, allowed_hosts=settings.trusted_hosts, www_redirect=False)
    app.add_middleware(SecurityHeaders)
    return app


class StrictJson:
    """JSON request bodies are strict JSON: ``NaN``, ``Infinity`` and ``-Infinity`` (which
    Python's json module accepts by default) are refused with 422 before any handler sees
    them, so no non-finite number can enter a config, a gate or a map. A JSON body is parsed
    whole in this process, so one over ``max_bytes`` is refused with 413 as it streams in
    (``MAPWISE_MAX_JSON_MB``), and one nested too deeply to parse with 422."""

    def __init__(self, app: ASGIApp, *, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        headers = dict(scope.get("headers", [])) if scope["type"] == "http" else {}
        if b"json" not in headers.get(b"content-type", b""):
            await self.app(scope, receive, send)
            return
        too_large = PayloadTooLargeError(
            f"the JSON body exceeds the limit of {self.max_bytes} bytes (MAPWISE_MAX_JSON_MB)",
            field="body",
        )
        length = headers.get(b"content-length")
        if length is not None and length.isdigit() and int(length) > self.max_bytes:
            await _send_error(send, too_large)
            return
        chunks: list[bytes] = []
        received = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                await self.app(scope, receive, send)  # a disconnect: nothing to check
                return
            chunks.append(message.get("body", b""))
            received += len(chunks[-1])
            if received > self.max_bytes:
                await _send_error(send, too_large)
                return
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        try:
            token = _non_finite_token(body)
        except RecursionError:
            await _send_error(
                send, InvalidRequestError("the JSON body is nested too deeply", field="body")
            )
            return
        if token is not None:
            error = InvalidRequestError(
                f"the body holds {token}, which is not a JSON number; numbers must be finite"
            )
            await _send_error(send, error)
            return
        delivered = False

        async def replay() -> Message:
            nonlocal delivered
            if delivered:
                return await receive()
            delivered = True
            return {"type": "http.request", "body": body, "more_body": False}

        await self.app(scope, replay, send)


def _non_finite_token(body: bytes) -> str | None:
    """``NaN``/``Infinity``/``-Infinity`` if the body (valid JSON otherwise) holds one."""
    found: list[str] = []

    def constant(name: str) -> float:
        found.append(name)
        return 0.0

    try:
        json.loads(body, parse_constant=constant)
    except ValueError:
        return None  # not JSON at all: the handler reports that
    return found[0] if found else None


class SecurityHeaders:
    """On every HTTP response: no MIME sniffing (a downloaded CSV is never run as a page),
    no framing by other sites, no referrer leaking run ids to other origins, and a
    Content-Security-Policy (a page that needs more, such as the dashboard's hashed import
    map, sets its own)."""

    HEADERS = (
        (b"x-content-type-options", b"nosniff"),
        (b"x-frame-options", b"DENY"),
        (b"referrer-policy", b"no-referrer"),
        (b"content-security-policy", DEFAULT_CSP.encode()),
    )

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                names = {k.lower() for k, _ in message.get("headers", [])}
                extra = [(k, v) for k, v in self.HEADERS if k not in names]
                message = {**message, "headers": [*message.get("headers", []), *extra]}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mapwise")
    except PackageNotFoundError:
        return "0+unknown"


class BodyLimit:
    """Refuse request bodies over ``max_bytes`` with 413, counting while they stream in
    (a lying or absent ``Content-Length`` does not help)."""

    def __init__(self, app: ASGIApp, *, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        error = PayloadTooLargeError(
            f"the request body exceeds the limit of {self.max_bytes} bytes", field="file"
        )
        length = dict(scope.get("headers", [])).get(b"content-length")
        if length is not None and length.isdigit() and int(length) > self.max_bytes:
            await _send_error(send, error)
            return
        received = 0
        exceeded = False
        started = False

        async def limited_receive() -> Message:
            nonlocal received, exceeded
            if exceeded:
                return {"type": "http.disconnect"}
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    exceeded = True
                    return {"type": "http.request", "body": b"", "more_body": False}
            return message

        async def guarded_send(message: Message) -> None:
            nonlocal started
            if exceeded:
                if message["type"] == "http.response.start" and not started:
                    started = True
                    await _send_error(send, error)
                return
            started = started or message["type"] == "http.response.start"
            await send(message)

        await self.app(scope, limited_receive, guarded_send)


async def _send_error(send: Send, error: AppError) -> None:
    body = json.dumps(error.body()).encode()
    headers: list[Any] = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        (b"connection", b"close"),
    ]
    await send({"type": "http.response.start", "status": error.status, "headers": headers})
    await send({"type": "http.response.body", "body": body})
