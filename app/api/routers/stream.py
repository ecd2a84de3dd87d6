"""``WS /api/runs/{id}/stream``: a full frame, then deltas (≤ live_fps per second) and
status changes. A viewer that falls behind gets a fresh full frame instead of the deltas it
missed; a finished run sends its final full frame and its status, and the socket stays open
(a resumed run streams again)."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any
from urllib.parse import urlsplit

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from starlette.concurrency import run_in_threadpool

from app.api.deps import Services, check_token, get_services
from app.api.schemas import RunOut
from app.config import Settings
from app.domain import FINISHED, MapVersion, Run, Series
from app.errors import AppError
from app.io.decimate import nested_or_none
from app.runs.frames import ErrorFrame, FullFrame, series_line
from app.runs.hub import LiveState

router = APIRouter(tags=["live"])

CLOSE_POLICY = 1008
CLOSE_NOT_FOUND = 4404


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


async def _full(services: Services, run_id: int) -> tuple[FullFrame, str]:
    """A full frame and the run's status: from the hub's live state while the run executes
    (one small query for the run document), else from the stored version and series."""
    if services.hub.state(run_id) is not None:
        run = await run_in_threadpool(services.runs.get, run_id)
        live = services.hub.state(run_id)  # read after the await: the freshest live state
        if live is not None and run.status not in FINISHED:
            return _full_from_live(run, live), live.status
    run, version, lines = await run_in_threadpool(_db_parts, services, run_id)
    return _full_from_db(run, version, lines), run.status


@router.websocket("/runs/{run_id}/stream")
async def stream_run(websocket: WebSocket, run_id: int) -> None:
    services = get_services(websocket)
    origin = websocket.headers.get("origin")
    if origin is not None and not _allowed_origin(origin, websocket, services.settings):
        # Browsers send their page's Origin on every WebSocket and CORS does not apply to
        # them: without this check any site a user visits could watch their runs.
        await websocket.close(code=CLOSE_POLICY, reason="origin not allowed")
        return
    try:
        await run_in_threadpool(check_token, services, websocket.query_params.get("token"))
    except AppError as exc:
        await websocket.close(code=CLOSE_POLICY, reason=exc.message[:120])
        return
    await websocket.accept()
    viewer = services.hub.subscribe(run_id)
    try:
        try:
            frame, status = await _full(services, run_id)
        except AppError as exc:
            await websocket.send_json(ErrorFrame(exc.body()["error"]).to_json())
            await websocket.close(code=CLOSE_NOT_FOUND)
            return
        viewer.reset()
        await websocket.send_json(frame.to_json())
        if status in FINISHED:
            await websocket.send_json(frame.status().to_json())
        receiver = asyncio.create_task(_drain_client(websocket))
        sender = asyncio.create_task(_send_loop(websocket, services, viewer, run_id))
        _done, pending = await asyncio.wait({receiver, sender}, return_when=asyncio.FIRST_COMPLETED)
        for task in pending:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
    except WebSocketDisconnect:
        pass
    finally:
        services.hub.unsubscribe(viewer)


def _allowed_origin(origin: str, websocket: WebSocket, settings: Settings) -> bool:
    """The dashboard's own origin (same host and port as the request), or a configured one."""
    host = websocket.headers.get("host", "")
    parsed = urlsplit(origin)
    if parsed.scheme in ("http", "https") and parsed.netloc and parsed.netloc == host:
        return True
    return origin in settings.cors_origins


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
                frame, status = await _full(services, run_id)
                viewer.reset()  # deltas queued meanwhile are already in the frame
                await websocket.send_json(frame.to_json())
                if status in FINISHED:
                    await websocket.send_json(frame.status().to_json())
                continue
            await websocket.send_text(message)
