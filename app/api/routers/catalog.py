"""Health and the estimator and scenario catalogs."""

from __future__ import annotations

from functools import cache
from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter

from app.api.deps import ServicesDep
from app.api.schemas import CatalogOut, HealthOut
from app.services.catalog import estimators, scenario_entries

router = APIRouter(tags=["catalog"])
open_router = APIRouter(tags=["health"])


@cache
def _version() -> str:
    """The installed package's version, looked up once: the lookup scans the distributions on
    ``sys.path`` and cost a polled ``/api/health`` a third of its CPU time."""
    try:
        return version("mapwise")
    except PackageNotFoundError:
        return "0+unknown"


@open_router.get("/health", response_model=HealthOut)
def health(services: ServicesDep) -> HealthOut:
    """Liveness, the database backend and its schema revision (no authentication)."""
    services.db.ping()
    return HealthOut(
        status="ok",
        database=services.db.backend,
        revision=services.revision,
        version=_version(),
        auth_required=services.settings.auth_required,
        workers=services.settings.run_workers,
        workers_alive=None if services.executor is None else services.executor.workers_alive(),
        loop_lag_ms=services.loop_lag.max_ms(),
        loop_cpu_s=services.loop_lag.cpu_s(),
    )


@router.get("/estimators", response_model=CatalogOut)
def list_estimators() -> CatalogOut:
    """Every estimator: roles of its signals, whether it needs a table, its config schema."""
    return CatalogOut(items=estimators())


@router.get("/scenarios", response_model=CatalogOut)
def list_scenarios() -> CatalogOut:
    """The simulation scenarios a dataset can be generated from."""
    return CatalogOut(items=scenario_entries())
