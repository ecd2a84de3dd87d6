"""``WS /api/runs/{id}/stream``: a full frame, then deltas (≤ live_fps per second) and
status changes. A viewer that falls behind gets a fresh full frame instead of the deltas it
missed; a finished run sends its final full frame and its status, and the socket stays open
(a resumed run streams again).

Before the handshake completes: an ``Origin`` outside the allowed hosts and CORS origins, a
missing or bad token, or a token without ``read`` is refused (close 1008, which is HTTP 403
at the handshake). A viewer over a limit (per run, per client address, in all) is accepted
and closed at once with 1013 "try again later" and the reason, which a browser can read.
A revoked token's sockets are closed with 1008 within :data:`REVOCATION_CHECK_S`.

``?encoding=binary`` asks for every message in the binary layout of
:mod:`app.runs.frame_encoding` (``json``, the default, sends text); any other value is
refused before the handshake completes (1008, the reason naming ``encoding``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import Any, cast
from urllib.parse import urlsplit

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from starlette.concurrency import run_in_threadpool

from app.api.deps import Services, authenticate, get_services, require_scope
from app.api.schemas import RunOut
from app.config import Settings
from app.domain import FINISHED, MapVersion, Run, Series
from app.errors import AppError
from app.io.decimate import nested_or_none
from app.runs.frame_encoding import ENCODINGS, Encoding, encode
from app.runs.frames import ErrorFrame, FullFrame, series_line
from app.runs.hub import EncodedFull, LiveState, Message, Viewer, ViewerLimitError

router = APIRouter(tags=["live"])
log = logging.getLogger("mapwise")

CLOSE_POLICY = 1008
CLOSE_TRY_AGAIN_LATER = 1013
CLOSE_NOT_FOUND = 4404
REVOCATION_CHECK_S = 0.25  # how often the tokens of open sockets are checked
STORED_FRAME_TTL_S = 1.0  # how long joiners of a run that is not executing share a frame


def _db_parts(services: Services, run_id: int) -> tuple[Run, MapVersion | None, list[Series]]:
    run = services.runs.get(run_id)
    version = services.runs.latest_version(run_id)
    _, lines = services.runs.series(run_id, points=services.settings.series_points)
    return run, version, lines


def _full_from_db(run: Run, version: MapVersion | None, lines: list[Series]) -> FullFrame:
    series = {x.name: series_line(x) for x in lines}
    axes = None if version is None else version.axes
    trajectory: dict[str, Any] = {"time": [], "points": []}
    if axes and all(a["name"] in series for a in axes):
        cols = [series[a["name"]]["values"] for a in axes]
        trajectory = {
            "time": series[axes[0]["name"]]["time"],
            "points": [list(p) for p in zip(*cols, strict=True)],
        }
    return FullFrame(
        run=RunOut.of(run).model_dump(mode="json"),
        axes=axes,
        values=None if version is None else nested_or_none(version.values),
        variances=None if version is None else nested_or_none(version.variances),
        visits=None if version is None else nested_or_none(version.visits),
        active_cell=None,
        trajectory=trajectory,
        series=series,
        metrics=dict(run.metrics),
        rejected=dict(run.rejected),
        sample=run.sample,
        n_samples=run.n_samples,
    )


def _full_from_live(run: Run, live: LiveState) -> FullFrame:
    doc = RunOut.of(run).model_dump(mode="json")
    doc |= {"status": live.status, "progress": live.progress, "sample": live.sample}
    return FullFrame(
        run=doc,
        axes=live.axes,
        values=live.values,
        variances=live.variances,
        visits=live.visits,
        active_cell=live.active_cell,
        trajectory={"time": list(live.trajectory_time), "points": list(live.trajectory_points)},
        series={
            name: {
                "unit": live.units.get(name, ""),
                "role": live.roles.get(name),
                "time": list(s["time"]),
                "values": list(s["values"]),
            }
            for name, s in live.series.items()
        },
        metrics=dict(live.metrics or {}),
        rejected=dict(live.rejected or {}),
        sample=live.sample,
        n_samples=live.n_samples,
    )


def _live_key(live: LiveState) -> tuple[Any, ...]:
    return ("live", live.seq, live.status)


def _reusable(full: EncodedFull | None, live: LiveState | None) -> bool:
    """A kept full frame still shows the run: the same live tick while the run executes,
    else a stored-state frame at most :data:`STORED_FRAME_TTL_S` old (a queued run can be
    cancelled without any worker telling the hub)."""
    if full is None:
        return False
    if live is not None:
        return full.key == _live_key(live)
    return full.key[0] == "db" and time.monotonic() - full.key[1] < STORED_FRAME_TTL_S


async def _full(services: Services, run_id: int) -> EncodedFull:
    """The run's full frame: from the hub's live state while the run executes (one small
    query for the run document), else from the stored version and series. Viewers joining at
    the same point share one build and skip the database (:attr:`LiveHub.full_frames`): a
    hundred joiners cost one query and one encoding per encoding they read."""
    hub = services.hub
    if _reusable(hub.full_frames.get(run_id), hub.state(run_id)):
        return hub.full_frames[run_id]
    async with hub.full_lock(run_id):
        if _reusable(hub.full_frames.get(run_id), hub.state(run_id)):
            return hub.full_frames[run_id]
        run = await run_in_threadpool(services.runs.get, run_id)
        live = hub.state(run_id)  # read after the await: the freshest live state
        if live is not None and run.status not in FINISHED:
            key, frame, status = _live_key(live), _full_from_live(run, live), live.status
        else:
            run, version, lines = await run_in_threadpool(_db_parts, services, run_id)
            key, frame, status = (
                ("db", time.monotonic()),
                _full_from_db(run, version, lines),
                run.status,
            )
        full = EncodedFull(
            key=key,
            doc=frame.to_json(),
            status_doc=frame.status().to_json() if status in FINISHED else None,
            status=status,
        )
        hub.keep_full(run_id, full)
        return full


@router.websocket("/runs/{run_id}/stream")
async def stream_run(websocket: WebSocket, run_id: int) -> None:
    services = get_services(websocket)
    origin = websocket.headers.get("origin")
    if origin is not None and not allowed_origin(origin, websocket, services.settings):
        # Browsers send their page's Origin on every WebSocket and CORS does not apply to
        # them: without this check any site a user visits could watch their runs.
        await websocket.close(code=CLOSE_POLICY, reason="origin not allowed")
        return
    encoding = websocket.query_params.get("encoding", "json")
    if encoding not in ENCODINGS:
        reason = f"encoding: must be one of {', '.join(ENCODINGS)}, not {encoding[:20]!r}"
        await websocket.close(code=CLOSE_POLICY, reason=reason)
        return
    secret = websocket.query_params.get("token")
    try:
        if services.settings.auth_required:
            caller = await run_in_threadpool(authenticate, services, secret)
        else:  # nothing to look up: no trip through the thread pool
            caller = authenticate(services, secret)
        require_scope(caller, "read", "watching a run")
    except AppError as exc:
        await websocket.close(code=CLOSE_POLICY, reason=exc.message[:120])
        return
    client = websocket.client.host if websocket.client else None
    try:
        viewer = services.hub.subscribe(
            run_id, client=client, token_id=caller.token_id, encoding=cast(Encoding, encoding)
        )
    except ViewerLimitError as exc:
        # Accepted first: a close before the handshake is a bare 403 a browser cannot read.
        await websocket.accept()
        await websocket.close(code=CLOSE_TRY_AGAIN_LATER, reason=exc.message[:120])
        return
    try:
        await websocket.accept()
        await _serve(websocket, services, viewer, run_id)
    except WebSocketDisconnect:
        pass
    finally:
        services.hub.unsubscribe(viewer)


async def _serve(websocket: WebSocket, services: Services, viewer: Viewer, run_id: int) -> None:
    try:
        full = await _full(services, run_id)
    except AppError as exc:
        await _send(websocket, encode(ErrorFrame(exc.body()["error"]).to_json(), viewer.encoding))
        await websocket.close(code=CLOSE_NOT_FOUND)
        return
    viewer.reset()
    await _send_full(websocket, services, viewer, full)
    receiver = asyncio.create_task(_drain_client(websocket))
    sender = asyncio.create_task(_send_loop(websocket, services, viewer, run_id))
    closed = asyncio.create_task(viewer.closed.wait())
    done, pending = await asyncio.wait(
        {receiver, sender, closed}, return_when=asyncio.FIRST_COMPLETED
    )
    for task in pending:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task
    if closed in done:
        with contextlib.suppress(WebSocketDisconnect, RuntimeError):
            await websocket.close(code=CLOSE_POLICY, reason=viewer.close_reason[:120])


def allowed_origin(origin: str, websocket: WebSocket, settings: Settings) -> bool:
    """A configured CORS origin, or an http(s) origin whose host is an allowed host.

    Never compared with the request's own ``Host``: under DNS rebinding the attacker's
    page and its requests both carry the attacker's name, so they would always match. Only
    when the allowlist is ``*`` (the Host check is off) is the Host what is left to match."""
    if origin in settings.cors_origins:
        return True
    parsed = urlsplit(origin)
    if parsed.scheme not in ("http", "https") or not parsed.hostname:
        return False
    host = parsed.hostname.lower()
    host = f"[{host}]" if ":" in host else host
    patterns = settings.trusted_hosts
    if "*" in patterns:
        return parsed.netloc.lower() == websocket.headers.get("host", "").lower()
    return any(host == p or (p.startswith("*.") and host.endswith(p[1:])) for p in patterns)


async def watch_revocations(services: Services, interval_s: float = REVOCATION_CHECK_S) -> None:
    """Close the sockets of revoked tokens, checking every ``interval_s``.

    Tokens are revoked by ``mapwise token revoke`` in another process, so the server learns
    of it from the database: one small query while sockets with tokens are open."""
    while True:
        await asyncio.sleep(interval_s)
        token_ids = services.hub.token_ids()
        if not token_ids:
            continue
        try:
            active = await run_in_threadpool(services.tokens.active_ids, token_ids)
        except Exception:  # the database is away: try again next time
            log.warning("cannot check the tokens of open sockets", exc_info=True)
            continue
        revoked = set(token_ids) - active
        if revoked:
            services.hub.close_tokens(revoked, "the token was revoked")


async def _drain_client(websocket: WebSocket) -> None:
    """Read (and ignore) what the client sends, until it goes away."""
    with contextlib.suppress(WebSocketDisconnect):
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return


async def _send_loop(websocket: WebSocket, services: Services, viewer: Any, run_id: int) -> None:
    with contextlib.suppress(WebSocketDisconnect, RuntimeError):
        while True:
            message = await viewer.next()
            if message is None:
                full = await _full(services, run_id)
                viewer.reset()  # deltas queued meanwhile are already in the frame
                await _send_full(websocket, services, viewer, full)
                continue
            await _send(websocket, message)


async def _send_full(
    websocket: WebSocket, services: Services, viewer: Viewer, full: EncodedFull
) -> None:
    frame, status = full.messages(services.hub, viewer.encoding)
    await _send(websocket, frame)
    if status is not None:
        await _send(websocket, status)


async def _send(websocket: WebSocket, message: Message) -> None:
    if isinstance(message, bytes):
        await websocket.send_bytes(message)
    else:
        await websocket.send_text(message)
