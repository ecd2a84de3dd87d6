"""Runs: create, list, get, rename, delete, clone, cancel, resume; versions, series, cells,
export, compare."""

from __future__ import annotations

import re
from typing import Annotated, Literal

from fastapi import APIRouter, Query, Response

from app.api.deps import MAX_ID, Id, ServicesDep
from app.api.schemas import (
    ERRORS,
    AxisOut,
    CellsOut,
    CompareItem,
    CompareOut,
    LabelIn,
    PageOut,
    RunGroupRefOut,
    RunOut,
    RunRenameIn,
    SeriesLine,
    SeriesOut,
    VersionOut,
    VersionSummaryOut,
)
from app.api.schemas_truth import TruthMapOut
from app.domain import RunStatus
from app.errors import InvalidRequestError
from app.io.decimate import finite_or_none, nested_or_none
from app.runs.options import MAX_VERSIONS
from app.services.run_clone import CloneRequest
from app.services.run_plan import RunRequest
from app.services.runs import GroupRef
from app.services.truth_map import truth_on_grid

router = APIRouter(tags=["runs"], responses=ERRORS)

Limit = Annotated[int, Query(ge=1, le=500)]
Offset = Annotated[int, Query(ge=0, le=MAX_ID)]


@router.post("/runs", status_code=201, response_model=RunOut)
def create_run(services: ServicesDep, body: RunRequest) -> RunOut:
    """Validate and queue a run. Service keys in ``config``: ``pace``, ``version_every``,
    ``gates``, ``locked``; the rest is the estimator's config."""
    return RunOut.of(services.runs.create(body))


@router.get("/runs", response_model=PageOut[RunOut])
def list_runs(
    services: ServicesDep,
    limit: Limit = 50,
    offset: Offset = 0,
    dataset_id: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None,
    status: RunStatus | None = None,
    # No control characters: names never hold one, and PostgreSQL text cannot hold NUL (a
    # query with one was a 500 there).
    q: Annotated[
        str | None,
        Query(
            max_length=200,
            pattern=r"^[^\x00-\x1f\x7f]*$",
            description="The name contains it (any case); no control characters.",
        ),
    ] = None,
    estimator: Annotated[str | None, Query(max_length=64, pattern=r"^[a-z0-9][a-z0-9-]*$")] = None,
    group: Annotated[
        int | None, Query(ge=1, le=MAX_ID, description="Only the runs of this sweep or batch.")
    ] = None,
    top_level: Annotated[
        bool,
        Query(
            description="Runs outside any sweep or batch, and each sweep or batch once, as its "
            "first run matching the filters (its ``group`` names it)."
        ),
    ] = False,
) -> PageOut:
    """Runs newest first, paged; every filter narrows the list. Each run's ``group`` names
    the sweep or batch it belongs to."""
    page = services.runs.list(
        limit=limit,
        offset=offset,
        dataset_id=dataset_id,
        status=status,
        q=q,
        estimator=estimator,
        group_id=group,
        top_level=top_level,
    )
    refs = services.runs.groups_of(page.items)
    return PageOut[RunOut](
        items=[RunOut.of(r, _group_out(refs.get(r.group_id or 0))) for r in page.items],
        total=page.total,
        limit=page.limit,
        offset=page.offset,
    )


@router.get("/runs/{run_id}", response_model=RunOut)
def get_run(services: ServicesDep, run_id: Id) -> RunOut:
    return RunOut.of(services.runs.get(run_id))


@router.patch("/runs/{run_id}", response_model=RunOut)
def rename_run(services: ServicesDep, run_id: Id, body: RunRenameIn) -> RunOut:
    """Rename the run (1 to 200 characters, no control characters)."""
    return RunOut.of(services.runs.rename(run_id, body.name))


@router.delete("/runs/{run_id}", status_code=204, response_class=Response)
def delete_run(services: ServicesDep, run_id: Id) -> Response:
    """Delete the run with its map versions, metrics and series. A queued or running run is
    refused (409 naming its status): cancel it first. Base maps promoted from it stay, their
    lineage naming the run; a sweep's or batch's run may go (the group counts what remains)."""
    services.runs.delete(run_id)
    return Response(status_code=204)


@router.post("/runs/{run_id}/clone", status_code=201, response_model=RunOut)
def clone_run(services: ServicesDep, run_id: Id, body: CloneRequest | None = None) -> RunOut:
    """Queue a new run with the run's dataset, estimator, signals, table and config, named
    "<name> (copy)"; the optional body overrides ``name`` and merges into ``config``, and the
    copy is validated exactly as ``POST /api/runs``. A sweep's run is cloned on its own."""
    return RunOut.of(services.runs.clone(run_id, body))


@router.post("/runs/{run_id}/cancel", response_model=RunOut)
def cancel_run(services: ServicesDep, run_id: Id) -> RunOut:
    """Cancel a queued or running run (a running run stops at its next chunk)."""
    return RunOut.of(services.runs.cancel(run_id))


@router.post("/runs/{run_id}/resume", response_model=RunOut)
def resume_run(services: ServicesDep, run_id: Id) -> RunOut:
    """Continue an interrupted or cancelled run from its last persisted version."""
    return RunOut.of(services.runs.resume(run_id))


@router.get("/runs/{run_id}/versions", response_model=PageOut[VersionSummaryOut])
def list_versions(
    services: ServicesDep,
    run_id: Id,
    limit: Annotated[int, Query(ge=1, le=MAX_VERSIONS + 1)] = MAX_VERSIONS + 1,
    offset: Offset = 0,
) -> PageOut:
    """The run's map versions by step (at most ``MAX_VERSIONS`` plus the final one, so the
    default page holds them all)."""
    page = services.runs.versions(run_id, limit=limit, offset=offset)
    return PageOut[VersionSummaryOut](
        items=[VersionSummaryOut.of(v) for v in page.items],
        total=page.total,
        limit=page.limit,
        offset=page.offset,
    )


@router.get("/runs/{run_id}/versions/{version_id}", response_model=VersionOut)
def get_version(services: ServicesDep, run_id: Id, version_id: Id) -> VersionOut:
    """One version by its database ``id`` (see ``by-number`` for its number in the run)."""
    return VersionOut.of_version(services.runs.version(run_id, version_id))


@router.get("/runs/{run_id}/versions/by-number/{number}", response_model=VersionOut)
def get_version_by_number(services: ServicesDep, run_id: Id, number: Id) -> VersionOut:
    """Version ``number`` of the run: its place 1…n by step, as the dashboard's URLs
    (``?version=N``), export headers and base-map names give it; 404 naming the number."""
    return VersionOut.of_version(services.runs.version_by_number(run_id, number))


@router.patch("/runs/{run_id}/versions/{version_id}", response_model=VersionSummaryOut)
def label_version(
    services: ServicesDep, run_id: Id, version_id: Id, body: LabelIn
) -> VersionSummaryOut:
    return VersionSummaryOut.of(services.runs.label(run_id, version_id, body.label))


@router.get("/runs/{run_id}/series", response_model=SeriesOut)
def get_series(
    services: ServicesDep,
    run_id: Id,
    points: Annotated[int, Query(ge=2, le=100_000)] = 2000,
) -> SeriesOut:
    """The run's result series on a shared time base (stored at the end of the run), at most
    ``points`` samples: each bucket's minimum and maximum, so one-sample spikes survive."""
    time, lines = services.runs.series(run_id, points=points)
    return SeriesOut(
        time=finite_or_none(time),
        series={
            x.name: SeriesLine(unit=x.unit, role=x.role, values=finite_or_none(x.values))
            for x in lines
        },
    )


@router.get("/runs/{run_id}/cells", response_model=CellsOut)
def get_cells(services: ServicesDep, run_id: Id) -> CellsOut:
    """Per cell: visits (interpolation weight of accepted samples) and rejections by reason."""
    version = services.runs.cells(run_id)
    if version is None:
        return CellsOut(axes=None, visits=None, rejected={})
    return CellsOut(
        axes=None if version.axes is None else [AxisOut(**a) for a in version.axes],
        visits=nested_or_none(version.visits),
        rejected={k: nested_or_none(v) or [] for k, v in version.cell_rejections.items()},
    )


@router.get("/runs/{run_id}/truth-map", response_model=TruthMapOut)
def get_truth_map(services: ServicesDep, run_id: Id) -> TruthMapOut:
    """A simulated dataset's true map on the run's grid (404 when the dataset has none)."""
    return TruthMapOut.of(truth_on_grid(services.db, run_id))


@router.get(
    "/runs/{run_id}/export",
    response_class=Response,
    responses={
        200: {
            "description": "The file",
            "content": {
                "application/json": {},
                "text/csv": {},
                "application/octet-stream": {},
                "text/plain": {},
                "application/xml": {},
            },
        }
    },
)
def export_run(
    services: ServicesDep,
    run_id: Id,
    format: Annotated[Literal["json", "csv", "mcap", "dcm", "cdfx", "image"], Query()] = "json",
    version: Annotated[
        int | None, Query(ge=1, le=MAX_ID, description="The version's database id.")
    ] = None,
    part: Literal["map", "series"] | None = None,
    number: Annotated[
        int | None,
        Query(
            ge=1, le=MAX_ID, description="The version's number 1…n in the run (not with version)."
        ),
    ] = None,
) -> Response:
    """Download: ``json`` (the ``mapwise adapt`` map document), ``csv`` (map grid, or
    ``part=series`` the time series), ``mcap`` (series + map versions), ``dcm``; a run
    linked to an A2L map also ``cdfx`` and ``image`` (the ECU's patched HEX/S19), its DCM
    and CDFX keyed by the A2L name with values as the ECU stores them. A map file is named
    ``run<R>-<estimator>-v<N>…`` and a DCM's header says "run R …, version N", N the version's
    number in the run."""
    if part == "series" and format in ("json", "dcm", "cdfx", "image"):
        raise InvalidRequestError(
            f"part=series is exported as CSV (format=csv) or MCAP; format={format} exports the "
            "map only",
            field="part",
        )
    download = services.exports.export(
        run_id, fmt=format, version_id=version, part=part, number=number
    )
    return Response(
        download.content,
        media_type=download.media_type,
        headers={"Content-Disposition": content_disposition(download.filename)},
    )


# One run id, 1..2**31-1 (MAX_ID) spelled in plain digits, as a regular expression, so that
# the schema states exactly what ``runs`` accepts.
_RUN_ID = (
    r"(?:[1-9][0-9]{0,8}|1[0-9]{9}|20[0-9]{8}|21[0-3][0-9]{7}|214[0-6][0-9]{6}|2147[0-3][0-9]{5}"
    r"|21474[0-7][0-9]{4}|214748[0-2][0-9]{3}|2147483[0-5][0-9]{2}|21474836[0-3][0-9]"
    r"|214748364[0-7])"
)
MAX_COMPARE = 20
RUN_IDS = re.compile(rf"^{_RUN_ID}(?:,{_RUN_ID}){{0,{MAX_COMPARE - 1}}}$")


@router.get("/compare", response_model=CompareOut)
def compare_runs(
    services: ServicesDep,
    runs: Annotated[
        str,
        Query(
            max_length=2000,
            description=f"1 to {MAX_COMPARE} comma-separated run ids, e.g. ``3,5``.",
            json_schema_extra={"pattern": RUN_IDS.pattern},
        ),
    ],
) -> CompareOut:
    """Several runs side by side, each with its final (or latest) map version."""
    if RUN_IDS.fullmatch(runs) is None:
        raise InvalidRequestError(
            f"runs must be 1 to {MAX_COMPARE} comma-separated run ids (1..{MAX_ID}) such as "
            f"'3,5'; got {runs[:80]!r}",
            field="runs",
        )
    ids = [int(x) for x in runs.split(",")]
    items = []
    for run, version in services.runs.compare(ids):
        doc = RunOut.of(run).model_dump()
        final = None if version is None else VersionOut.of_version(version)
        items.append(CompareItem(**doc, final_version=final))
    return CompareOut(runs=items)


def _group_out(ref: GroupRef | None) -> RunGroupRefOut | None:
    if ref is None:
        return None
    return RunGroupRefOut(id=ref.id, kind=ref.kind, name=ref.name, size=ref.size)  # type: ignore[arg-type]


def content_disposition(filename: str) -> str:
    """``attachment`` with a filename that cannot break out of the header or the path:
    ASCII letters, digits, ``._-`` only (RFC 6266), at most 120 characters."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", filename).strip("._") or "download"
    return f'attachment; filename="{safe[:120]}"'
