"""Sweeps (one dataset × many settings, ranked) and fleet batches (many datasets × one
config, merged): create, list, get."""

from __future__ import annotations

from collections import Counter
from typing import Annotated, Any

from fastapi import APIRouter, Query

from app.api.deps import MAX_ID, Id, ServicesDep
from app.api.schemas import ERRORS, AggregateOut, AxisOut, BatchOut, GroupOut, GroupRunOut, PageOut
from app.io.decimate import nested_or_none
from app.services.sweeps import BatchRequest, GroupView, SweepRequest, rank

router = APIRouter(tags=["sweeps and batches"], responses=ERRORS)

Limit = Annotated[int, Query(ge=1, le=500)]
Offset = Annotated[int, Query(ge=0, le=MAX_ID)]


def _out(view: GroupView) -> dict[str, Any]:
    group = view.group
    runs = rank(group, view.runs) if group.kind == "sweep" else view.runs
    items = [
        GroupRunOut(
            id=r.id,
            dataset_id=r.dataset_id,
            status=r.status,
            params=r.params,
            metric=r.metrics.get(group.metric) if group.metric else None,
            metrics=r.metrics,
            error=r.error,
        )
        for r in runs
    ]
    best = next((i.id for i in items if i.metric is not None), None)
    return {
        "id": group.id,
        "kind": group.kind,
        "name": group.name,
        "estimator": group.estimator,
        "metric": group.metric,
        "order": group.order,
        "created_at": group.created_at,
        "request": group.request,
        "counts": dict(Counter(r.status for r in runs)),
        "runs": items,
        "best_run_id": best if group.kind == "sweep" else None,
    }


@router.post("/sweeps", status_code=201, response_model=GroupOut)
def create_sweep(services: ServicesDep, body: SweepRequest) -> GroupOut:
    """Queue one run per parameter set: the grid of the value lists, or ``samples`` seeded
    random draws. Every run is validated before any is stored."""
    return GroupOut(**_out(services.sweeps.create_sweep(body)))


@router.get("/sweeps", response_model=PageOut[GroupOut])
def list_sweeps(services: ServicesDep, limit: Limit = 50, offset: Offset = 0) -> PageOut:
    return _page(services, "sweep", limit, offset)


@router.get("/sweeps/{sweep_id}", response_model=GroupOut)
def get_sweep(services: ServicesDep, sweep_id: Id) -> GroupOut:
    """The sweep with its runs, best first by its metric."""
    return GroupOut(**_out(services.sweeps.get(sweep_id, "sweep")))


@router.post("/batches", status_code=201, response_model=BatchOut)
def create_batch(services: ServicesDep, body: BatchRequest) -> BatchOut:
    """Queue the same run on every dataset of a fleet."""
    return BatchOut(**_out(services.sweeps.create_batch(body)))


@router.get("/batches", response_model=PageOut[GroupOut])
def list_batches(services: ServicesDep, limit: Limit = 50, offset: Offset = 0) -> PageOut:
    return _page(services, "batch", limit, offset)


@router.get("/batches/{batch_id}", response_model=BatchOut)
def get_batch(services: ServicesDep, batch_id: Id) -> BatchOut:
    """The batch with its runs and, once all succeeded, the aggregate map."""
    doc = _out(services.sweeps.get(batch_id, "batch"))
    agg = services.sweeps.aggregate(batch_id)
    if agg is not None:
        doc["aggregate"] = AggregateOut(
            axes=[AxisOut(**a) for a in agg["axes"]],
            run_ids=agg["run_ids"],
            values=nested_or_none(agg["values"]) or [],
            variances=nested_or_none(agg["variances"]),
            weights=[nested_or_none(w) or [] for w in agg["weights"]],
            z=None if agg["z"] is None else [nested_or_none(z) or [] for z in agg["z"]],
            deviating_cells=agg["deviating_cells"],
        )
    return BatchOut(**doc)


def _page(services: Any, kind: str, limit: int, offset: int) -> PageOut:
    page = services.sweeps.list(kind, limit=limit, offset=offset)
    items = [GroupOut(**_out(services.sweeps.get(g.id, kind))) for g in page.items]
    return PageOut[GroupOut](items=items, total=page.total, limit=page.limit, offset=page.offset)
