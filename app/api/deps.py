"""Dependencies: the services of the running app, and bearer-token authentication."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from fastapi import Depends, Path, Request
from starlette.requests import HTTPConnection

from app.api.loop_lag import LoopLag
from app.config import Settings
from app.db.engine import Database
from app.errors import UnauthorizedError
from app.runs.executor import Executor
from app.runs.hub import LiveHub
from app.services.base_maps import BaseMapService
from app.services.datasets import DatasetService
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
    sweeps: SweepService
    base_maps: BaseMapService
    tokens: TokenService
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


def check_token(services: Services, secret: str | None) -> None:
    """Raise 401 unless auth is off or ``secret`` is an active token."""
    if not services.settings.auth_required:
        return
    if not secret:
        raise UnauthorizedError("this server requires a bearer token (mapwise token create)")
    if services.tokens.verify(secret) is None:
        raise UnauthorizedError("the bearer token is unknown or revoked")


def _bearer(header: str | None) -> str | None:
    if not header:
        return None
    scheme, _, value = header.partition(" ")
    return value.strip() if scheme.lower() == "bearer" and value.strip() else None


def require_token(request: Request) -> None:
    check_token(get_services(request), _bearer(request.headers.get("authorization")))
