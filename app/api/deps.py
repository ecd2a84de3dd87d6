"""Dependencies: the services of the running app, bearer-token authentication and scopes.

Every ``/api`` route needs a scope (docs/security.md): reading needs ``read``; what starts
work (uploads, runs, sweeps, cancel, resume, labels) needs ``run``; what destroys data or
changes shared starting points (deletes, base maps) needs ``admin``. The table is
:data:`ROUTE_SCOPES`; a writing route missing from it needs ``admin`` (fail closed). With auth
off (loopback, no ``MAPWISE_REQUIRE_AUTH``) the caller has every scope.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from fastapi import Depends, Path, Request
from starlette.requests import HTTPConnection

from app.api.loop_lag import LoopLag
from app.config import Settings
from app.db.engine import Database
from app.domain import SCOPES
from app.errors import InsufficientScopeError, UnauthorizedError
from app.runs.executor import Executor
from app.runs.hub import LiveHub
from app.services.base_maps import BaseMapService
from app.services.datasets import DatasetService
from app.services.ecus import EcuService
from app.services.run_exports import RunExports
from app.services.runs import RunService
from app.services.sweeps import SweepService
from app.services.tokens import TokenService


@dataclass
class Services:
    settings: Settings
    db: Database
    hub: LiveHub
    executor: Executor | None
    datasets: DatasetService
    runs: RunService
    exports: RunExports
    sweeps: SweepService
    base_maps: BaseMapService
    tokens: TokenService
    ecus: EcuService
    revision: str | None = None
    loop_lag: LoopLag = field(default_factory=LoopLag)


def get_services(connection: HTTPConnection) -> Services:
    return connection.app.state.services


ServicesDep = Annotated[Services, Depends(get_services)]

MAX_ID = 2**31 - 1  # the databases' INTEGER: larger ids cannot exist, so they are a 422
Id = Annotated[int, Path(ge=1, le=MAX_ID)]


def get_settings(connection: HTTPConnection) -> Settings:
    return connection.app.state.settings


SettingsDep = Annotated[Settings, Depends(get_settings)]


ROUTE_SCOPES: dict[str, str] = {
    "POST /datasets": "run",
    "POST /datasets/simulate": "run",
    "POST /datasets/simulate/stream": "run",
    "DELETE /datasets/{dataset_id}": "admin",
    "POST /runs": "run",
    "POST /runs/{run_id}/cancel": "run",
    "POST /runs/{run_id}/resume": "run",
    "PATCH /runs/{run_id}": "run",
    "POST /runs/{run_id}/clone": "run",
    "DELETE /runs/{run_id}": "admin",
    "PATCH /runs/{run_id}/versions/{version_id}": "run",
    "POST /base-maps": "admin",
    "POST /sweeps": "run",
    "POST /batches": "run",
    "POST /ecus": "run",
    "PUT /ecus/{ecu_id}/values": "run",
    "DELETE /ecus/{ecu_id}": "admin",
    "POST /ecus/{ecu_id}/maps/{name}/base-map": "admin",
}
READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


@dataclass(frozen=True, slots=True)
class Caller:
    """Who is asking: their token (``None`` with auth off) and what they may do."""

    token_id: int | None
    scopes: tuple[str, ...]
    auth_required: bool


def route_scope(method: str, path: str) -> str:
    """The scope ``method`` on the route template ``path`` (with or without ``/api``) needs."""
    path = path.removeprefix("/api")
    scope = ROUTE_SCOPES.get(f"{method.upper()} {path}")
    if scope is not None:
        return scope
    return "read" if method.upper() in READ_METHODS else "admin"


def authenticate(services: Services, secret: str | None) -> Caller:
    """The caller behind ``secret``; 401 unless auth is off or it is an active token."""
    if not services.settings.auth_required:
        return Caller(token_id=None, scopes=SCOPES, auth_required=False)
    if not secret:
        raise UnauthorizedError("this server requires a bearer token (mapwise token create)")
    token = services.tokens.verify(secret)
    if token is None:
        raise UnauthorizedError("the bearer token is unknown or revoked")
    return Caller(token_id=token.id, scopes=token.scopes, auth_required=True)


def require_scope(caller: Caller, scope: str, what: str) -> None:
    """403 ``insufficient_scope`` unless ``caller`` has ``scope``."""
    if scope not in caller.scopes:
        raise InsufficientScopeError(
            f"this token lacks the {scope!r} scope that {what} needs "
            f"(it has {', '.join(caller.scopes) or 'none'}); "
            f"create one with `mapwise token create --scope {scope}`",
            scope=scope,
        )


def _bearer(header: str | None) -> str | None:
    if not header:
        return None
    scheme, _, value = header.partition(" ")
    return value.strip() if scheme.lower() == "bearer" and value.strip() else None


def require_token(request: Request) -> Caller:
    """The dependency of every ``/api`` route: a valid token with the route's scope."""
    caller = authenticate(get_services(request), _bearer(request.headers.get("authorization")))
    route = request.scope.get("route")
    template = getattr(route, "path", None) or request.url.path
    scope = route_scope(request.method, template)
    require_scope(caller, scope, f"{request.method} {request.url.path}")
    request.state.caller = caller
    return caller


CallerDep = Annotated[Caller, Depends(require_token)]
