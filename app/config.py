"""Service settings, read from ``MAPWISE_*`` environment variables (pydantic-settings).

Nonsense fails at start-up, not at the first request. The app receives its settings from
:func:`create_app` (tests pass their own); :func:`get_settings` is the cached default.
"""

from __future__ import annotations

import ipaddress
import os
from functools import lru_cache
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

DEFAULT_DATABASE_URL = "sqlite:///./mapwise.db"


class Settings(BaseSettings):
    """Everything the service can be told; every field is ``MAPWISE_<NAME>`` in the env."""

    model_config = SettingsConfigDict(env_prefix="MAPWISE_", extra="ignore", frozen=True)

    database_url: str = Field(
        DEFAULT_DATABASE_URL,
        description="SQLAlchemy URL: sqlite:///path.db or postgresql+psycopg://user@host/db.",
    )
    host: str = Field("127.0.0.1", description="Interface `mapwise serve` binds to.")
    port: int = Field(8000, ge=0, le=65535, description="TCP port of `mapwise serve`.")
    require_auth: bool | None = Field(
        None,
        description="Bearer tokens required; default: whenever the host is not loopback.",
    )
    cors_origins: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description="Origins allowed by CORS (comma-separated in the env); none by default.",
    )
    max_upload_mb: float = Field(512.0, gt=0, description="Largest accepted upload, in MiB.")
    max_decompressed_mb: float = Field(
        512.0,
        gt=0,
        description="Most an MCAP or MDF4 upload may inflate to (compressed chunks), in MiB.",
    )
    run_workers: int = Field(
        default_factory=lambda: max(2, min(8, os.cpu_count() or 2)),
        ge=1,
        le=64,
        description="Processes executing runs in parallel.",
    )
    version_fraction: float = Field(
        0.1,
        gt=0,
        le=1,
        description="Default map-version cadence as a fraction of the log (0.1: every 10 %).",
    )
    live_fps: float = Field(20.0, gt=0, le=60, description="Most live frames per second.")
    series_points: int = Field(
        4000, ge=100, le=100_000, description="Points kept per stored result series."
    )
    cancel_poll_s: float = Field(
        0.2, gt=0, le=10, description="How often a running run checks for cancel requests."
    )
    seed_demo: bool = Field(True, description="Seed a demo dataset and run on an empty DB.")
    executor: Literal["local", "dask"] = Field(
        "local",
        description="Where runs execute: a local process pool, or a Dask distributed cluster "
        "sharing the PostgreSQL database.",
    )
    dask_address: str | None = Field(
        None, description="Dask scheduler address (tcp://host:8786) when executor=dask."
    )
    dask_timeout_s: float = Field(
        30.0, gt=0, le=600, description="How long to wait for the Dask scheduler at start-up."
    )
    heartbeat_s: float = Field(
        2.0, gt=0, le=60, description="How often an executing run proves it is alive."
    )
    heartbeat_timeout_s: float = Field(
        30.0,
        gt=0,
        le=3600,
        description="A running run silent this long is a lost attempt (its worker died).",
    )
    lost_run_policy: Literal["interrupt", "requeue"] = Field(
        "interrupt",
        description="A lost attempt leaves the run interrupted (resume by hand) or queued.",
    )
    max_lost_attempts: int = Field(
        3, ge=1, le=100, description="Lost attempts after which a run fails (a poison run)."
    )

    @field_validator("cors_origins", mode="before")
    @classmethod
    def _split_origins(cls, value: object) -> object:
        if isinstance(value, str):
            return [o.strip() for o in value.split(",") if o.strip()]
        return value

    @field_validator("database_url")
    @classmethod
    def _known_backend(cls, url: str) -> str:
        if not url.startswith(("sqlite", "postgresql")):
            raise ValueError(f"must be a sqlite:// or postgresql:// URL, got {url!r}")
        return url

    @model_validator(mode="after")
    def _auth_beyond_loopback(self) -> Settings:
        if self.require_auth is False and not is_loopback(self.host):
            raise ValueError(
                f"require_auth=false is not allowed when listening on {self.host!r} "
                "(beyond loopback); create a token with `mapwise token create`"
            )
        return self

    @model_validator(mode="after")
    def _dask_needs_an_address_and_a_shared_database(self) -> Settings:
        if self.executor == "dask":
            if not self.dask_address:
                raise ValueError("executor=dask needs dask_address (tcp://scheduler:8786)")
            if not self.database_url.startswith("postgresql"):
                raise ValueError(
                    "executor=dask needs a database its workers share: a postgresql:// URL"
                )
        return self

    @model_validator(mode="after")
    def _heartbeat_within_timeout(self) -> Settings:
        if self.heartbeat_timeout_s < 3 * self.heartbeat_s:
            raise ValueError(
                f"heartbeat_timeout_s ({self.heartbeat_timeout_s:g}) must be at least 3 "
                f"heartbeats (heartbeat_s = {self.heartbeat_s:g})"
            )
        return self

    @property
    def auth_required(self) -> bool:
        return bool(self.require_auth) or not is_loopback(self.host)

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 1024 * 1024)

    @property
    def max_decompressed_bytes(self) -> int:
        return int(self.max_decompressed_mb * 1024 * 1024)

    @property
    def backend(self) -> Literal["sqlite", "postgresql"]:
        return "sqlite" if self.database_url.startswith("sqlite") else "postgresql"


def is_loopback(host: str) -> bool:
    """``localhost`` and loopback addresses; ``0.0.0.0``/``::`` and names are not."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@lru_cache
def get_settings() -> Settings:
    return Settings()
