"""Datasets: upload (multipart), simulate, list, get, preview, delete."""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import AsyncIterator
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, Query, Response, UploadFile
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from app.allocators import give_back_free_memory
from app.api.deps import MAX_ID, Id, Services, ServicesDep
from app.api.schemas import (
    ERRORS,
    DatasetOut,
    DatasetSetupOut,
    PageOut,
    PreviewChannel,
    PreviewOut,
    SimulateIn,
)
from app.errors import AppError, InvalidRequestError
from app.io.names import name_schema
from app.services.scenario_setup import setup_of
from estimation.errors import EstimationError
from estimation.progress import Progress

log = logging.getLogger("mapwise")
router = APIRouter(prefix="/datasets", tags=["datasets"], responses=ERRORS)
# ``{dataset_id:int}``: only digits match, so ``GET /datasets/simulate`` reaches the POST-only
# route of that path (405, Allow: POST) instead of failing as an id (422).

Limit = Annotated[int, Query(ge=1, le=500)]
Offset = Annotated[int, Query(ge=0, le=MAX_ID)]


def _units(raw: str | None) -> dict[str, str] | None:
    if raw is None or not raw.strip():
        return None
    try:
        units = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise InvalidRequestError(f"units must be a JSON object: {exc.msg}", field="units") from exc
    except RecursionError:
        raise InvalidRequestError("units is nested too deeply", field="units") from None
    if not isinstance(units, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in units.items()
    ):
        raise InvalidRequestError(
            'units must be a JSON object of strings, e.g. {"speed": "rpm"}', field="units"
        )
    return units


def _channels(raw: str | None) -> list[str] | None:
    """``a, b`` or a JSON array ``["a,b", "c"]`` (for names holding a comma); blank: all."""
    if raw is None or not raw.strip():
        return None
    if raw.lstrip().startswith("["):
        try:
            names = json.loads(raw)
        except json.JSONDecodeError as exc:
            raise InvalidRequestError(
                f"channels must be a comma-separated list or a JSON array: {exc.msg}",
                field="channels",
            ) from exc
        except RecursionError:
            raise InvalidRequestError("channels is nested too deeply", field="channels") from None
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise InvalidRequestError(
                'channels must be a JSON array of strings, e.g. ["rpm", "load"]',
                field="channels",
            )
    else:
        names = raw.split(",")
    kept = [n.strip() for n in names if n.strip()]
    return kept or None


@router.post("", status_code=201, response_model=DatasetOut)
def upload_dataset(
    services: ServicesDep,
    file: Annotated[
        UploadFile, File(description="CSV, MCAP, MDF4 or MDF3 log (format from content).")
    ],
    name: Annotated[str | None, Form(max_length=200, json_schema_extra=name_schema)] = None,
    units: Annotated[str | None, Form(description='JSON object {"channel": "unit"}')] = None,
    channels: Annotated[
        str | None,
        Form(
            max_length=200_000,
            description="Channels to keep, named as recorded: comma-separated, or a JSON "
            "array of strings. Default: all.",
        ),
    ] = None,
    raster: Annotated[
        str | None,
        Form(
            max_length=1000,
            description="Time base: a rate ('100Hz', '1kHz'), a step ('10ms', '0.1s') or "
            "'channel:NAME'. Default: the raster of the slowest kept channel.",
        ),
    ] = None,
    rate_hz: Annotated[
        float | None,
        Form(
            gt=0,
            le=1e7,
            allow_inf_nan=False,
            description="Sample rate of the rows in Hz, for a CSV without a time column only "
            "(row k at k / rate_hz s); such a file is refused (422, field 'time') without it.",
        ),
    ] = None,
) -> DatasetOut:
    """Upload a log. The whole file is validated before anything is stored. The response
    also carries ingest's ``notes`` and the ``masked`` samples per channel, when there are
    any; they are stored with the dataset, so ``GET`` gives them too."""
    try:
        dataset = services.datasets.upload(
            file.file,
            filename=file.filename,
            name=name,
            units=_units(units),
            max_bytes=services.settings.max_upload_bytes,
            max_whole_bytes=services.settings.max_whole_bytes,
            max_decompressed_bytes=services.settings.max_decompressed_bytes,
            channels=_channels(channels),
            raster=raster,
            rate_hz=rate_hz,
        )
    finally:  # a refused upload parsed as much as an accepted one may have
        give_back_free_memory()
    return DatasetOut.of(dataset)


@router.post("/simulate", status_code=201, response_model=DatasetOut)
def simulate_dataset(services: ServicesDep, body: SimulateIn) -> DatasetOut:
    """A dataset simulated from a scenario; its truth is kept for the run metrics."""
    return _simulate(services, body, None)


def _simulate(services: Services, body: SimulateIn, progress: Progress | None) -> DatasetOut:
    dataset = services.datasets.simulate(
        body.scenario,
        seed=body.seed,
        name=body.name,
        duration_s=body.duration_s,
        mismatch=body.mismatch,
        progress=progress,
    )
    return DatasetOut.of(dataset)


PROGRESS_EVERY_S = 0.25
"""Seconds between the progress lines of ``POST /datasets/simulate/stream``."""


@router.post(
    "/simulate/stream",
    response_class=StreamingResponse,
    responses={
        200: {
            "content": {"application/x-ndjson": {}},
            "description": "One JSON document a line: {progress, stage} every 0.25 s while "
            "the scenario is simulated (progress: share of the current plant run's integrator "
            "steps, 0-1; stage: that run's number, from 1; 0 before the first), then "
            "{dataset} (the 201 body of POST /datasets/simulate) "
            "or {error, status} (the error body and the status the plain route answers).",
        }
    },
)
async def simulate_dataset_stream(services: ServicesDep, body: SimulateIn) -> StreamingResponse:
    """``POST /datasets/simulate`` with progress: the same body, the same dataset, streamed as
    newline-delimited JSON (docs/rest-api.md#simulate-progress). ``progress`` is the plant
    integrator's share of steps done (:mod:`estimation.progress`), not a time estimate."""
    # Every 422 of the plain route that does not need the simulation, before the stream.
    services.datasets.check_simulation(body.scenario, body.duration_s, body.name)
    progress = Progress()

    async def lines() -> AsyncIterator[bytes]:
        task = asyncio.ensure_future(run_in_threadpool(_simulate, services, body, progress))
        # A client that leaves mid-stream does not stop the simulation (the dataset is stored
        # as by the plain route); its outcome is then read here, so nothing goes unretrieved.
        task.add_done_callback(lambda t: t.cancelled() or t.exception())
        while True:
            yield _line({"progress": round(progress.fraction, 4), "stage": progress.stage})
            done, _ = await asyncio.wait({task}, timeout=PROGRESS_EVERY_S)
            if done:
                break
        try:
            out = task.result()
        except AppError as exc:
            yield _line(exc.body() | {"status": exc.status})
        except EstimationError as exc:
            error = InvalidRequestError(" ".join(str(exc).split()))
            yield _line(error.body() | {"status": error.status})
        except Exception as exc:  # the status line is sent: the error goes in the stream
            log.exception("simulation failed", exc_info=exc)
            error = AppError("internal error; see the server log")
            error.code = "internal_error"
            yield _line(error.body() | {"status": error.status})
        else:
            yield _line({"progress": 1.0, "stage": progress.stage})
            yield _line({"dataset": out.model_dump(mode="json")})

    return StreamingResponse(lines(), media_type="application/x-ndjson")


def _line(document: dict[str, Any]) -> bytes:
    return (json.dumps(document) + "\n").encode()


@router.get("", response_model=PageOut[DatasetOut])
def list_datasets(services: ServicesDep, limit: Limit = 50, offset: Offset = 0) -> PageOut:
    page = services.datasets.list(limit=limit, offset=offset)
    return PageOut[DatasetOut](
        items=[DatasetOut.of(d) for d in page.items],
        total=page.total,
        limit=page.limit,
        offset=page.offset,
    )


@router.get("/{dataset_id:int}", response_model=DatasetOut)
def get_dataset(services: ServicesDep, dataset_id: Id) -> DatasetOut:
    return DatasetOut.of(services.datasets.get(dataset_id))


@router.get("/{dataset_id:int}/preview", response_model=PreviewOut)
def preview_dataset(
    services: ServicesDep,
    dataset_id: Id,
    points: Annotated[int, Query(ge=4, le=20_000)] = 400,
) -> PreviewOut:
    """Every channel decimated to at most ``points`` samples, peaks kept."""
    doc = services.datasets.preview(dataset_id, points=points)
    return PreviewOut(
        time=doc["time"],
        channels={k: PreviewChannel(**v) for k, v in doc["channels"].items()},
    )


@router.get("/{dataset_id:int}/setup", response_model=DatasetSetupOut)
def dataset_setup(services: ServicesDep, dataset_id: Id) -> DatasetSetupOut:
    """A simulated dataset's scenario setup per estimator it applies to: the table grid,
    signals and config a run starts from (the scenario's settings with this realisation's
    drawn constants); no estimators for an uploaded log."""
    return DatasetSetupOut(**setup_of(services.db, dataset_id))


@router.delete("/{dataset_id:int}", status_code=204, response_class=Response)
def delete_dataset(services: ServicesDep, dataset_id: Id, force: bool = False) -> Response:
    """Delete a dataset; 409 if runs use it, unless ``force`` (then they go too)."""
    services.datasets.delete(dataset_id, force=force)
    return Response(status_code=204)
