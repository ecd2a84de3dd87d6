"""Service settings, read from ``MAPWISE_*`` environment variables (pydantic-settings).

Nonsense fails at start-up, not at the first request. The app receives its settings from
:func:`create_app` (tests pass their own); :func:`get_settings` is the cached default.
"""

from __future__ import annotations

import ipaddress
import os
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

DEFAULT_DATABASE_URL = "sqlite:///./mapwise.db"
# A map cell written as text: a number of up to 17 significant digits and its separators,
# with room for a DCM's keywords or a JSON document's brackets.
MAP_FILE_BYTES_PER_CELL = 32


def physical_memory_mb() -> float | None:
    """The machine's physical memory in MiB, or ``None`` where the OS does not say."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**20
    except (AttributeError, ValueError, OSError):
        return None


def default_run_memory_mb(run_workers: int) -> float:
    """A quarter of physical memory shared by the run workers, 512 MiB to 4 GiB per run.

    With the quarter split between the workers, all of them at their budget still leave
    three quarters of the host to the API, the database and everything else.
    """
    total = physical_memory_mb()
    if total is None:
        return 1024.0
    return float(max(512, min(4096, int(0.25 * total / max(1, run_workers)))))


class Settings(BaseSettings):
    """Everything the service can be told; every field is ``MAPWISE_<NAME>`` in the env."""

    model_config = SettingsConfigDict(env_prefix="MAPWISE_", extra="ignore", frozen=True)

    database_url: str = Field(
        DEFAULT_DATABASE_URL,
        description="SQLAlchemy URL: sqlite:///path.db or postgresql+psycopg://user@host/db.",
    )
    store_url: str = Field(
        "./mapwise-data/",
        description="Artifact store of the datasets' samples (one Parquet file each): a "
        "directory, resolved against the working directory at start-up, or an fsspec URL "
        "(file:///…, memory://…, s3://… with s3fs installed). Back it up with the database.",
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
    max_upload_mb: float = Field(
        2048.0,
        gt=0,
        description="Largest accepted upload, in MiB. A dense CSV log streams to the store; "
        "anything else is also held to max_whole_mb.",
    )
    max_whole_mb: float = Field(
        512.0,
        gt=0,
        description="Largest upload read whole into memory, in MiB: an MCAP, MDF or "
        "non-dense CSV log, an A2L or a values file (never more than max_upload_mb).",
    )
    max_json_mb: float = Field(
        16.0,
        gt=0,
        description="Largest JSON request body, in MiB (a 250,000-cell map fits in about 6); "
        "it is parsed whole in the API process.",
    )
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
    run_workers_prestart: bool = Field(
        True,
        description="Start every run worker at start-up, so the first run does not wait about "
        "1 s for one to import and load the kernels; off: a worker starts with the first run "
        "that needs it, and a server that runs nothing holds no worker's memory (about "
        "300 MiB each).",
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
    run_memory_mb: float = Field(
        default_factory=lambda data: default_run_memory_mb(data.get("run_workers", 2)),
        ge=256,
        description="Memory budget of one run, in MiB: runs predicted to need more are "
        "refused at creation, and each run worker is held to it by the OS. Default: a "
        "quarter of physical memory divided by run_workers, 512 to 4096.",
    )
    run_max_s: float = Field(
        6 * 3600.0,
        gt=0,
        description="Wall-clock budget of one run attempt, in seconds: a paced run predicted "
        "to take longer is refused, and an attempt that overruns it fails.",
    )
    max_cells: int = Field(
        250_000,
        ge=1,
        le=10_000_000,
        description="Most cells of a table or base map (estimators may declare a lower cap).",
    )
    run_versions_mb: float = Field(
        512.0,
        gt=0,
        description="Most bytes of stored map versions one run may write, in MiB.",
    )
    sweep_versions_mb: float = Field(
        8192.0,
        gt=0,
        description="Most bytes of stored map versions the runs of one sweep or batch may "
        "write in all (their predicted sum), in MiB.",
    )

    cache_dir: Path | None = Field(
        None,
        description="Where parsed A2L files are cached (by content hash); default "
        "$XDG_CACHE_HOME/mapwise, else ~/.cache/mapwise.",
    )
    cache_mb: float = Field(
        512.0, gt=0, description="Most bytes the A2L cache keeps, in MiB (oldest go first)."
    )
    cache_files: int = Field(
        256, ge=1, le=100_000, description="Most files the A2L cache keeps (oldest go first)."
    )

    allowed_hosts: Annotated[list[str] | None, NoDecode] = Field(
        None,
        description="Host names the server answers to (comma-separated in the env; `*` "
        "turns the check off). Any other Host header gets 400, which defeats DNS rebinding. "
        "Default: localhost, 127.0.0.1 and [::1], plus `host` when it is not a wildcard.",
    )
    max_viewers_per_run: int = Field(
        100, ge=1, le=100_000, description="Most live WebSocket viewers of one run."
    )
    max_viewers_per_client: int = Field(
        200,
        ge=1,
        le=100_000,
        description="Most live WebSocket viewers from one client address (all runs).",
    )
    max_viewers: int = Field(
        500, ge=1, le=1_000_000, description="Most live WebSocket viewers of the server."
    )
    ws_deflate: bool = Field(
        False,
        description=(
            "Offer permessage-deflate on WebSockets. Off by default: it compresses every frame "
            "once per viewer on the event loop (a third of the loop's time with 20 viewers), "
            "and live frames are small next to a LAN's bandwidth."
        ),
    )

    @field_validator("cors_origins", mode="before")
    @classmethod
    def _split_origins(cls, value: object) -> object:
        if isinstance(value, str):
            return [o.strip() for o in value.split(",") if o.strip()]
        return value

    @field_validator("allowed_hosts", mode="before")
    @classmethod
    def _split_hosts(cls, value: object) -> object:
        if isinstance(value, str):
            value = value.split(",")
        if isinstance(value, list | tuple):
            hosts = [_host_name(str(h)) for h in value if str(h).strip()]
            for host in hosts:
                if "*" in host[1:] or (
                    host.startswith("*") and host != "*" and not host.startswith("*.")
                ):
                    raise ValueError(f"{host!r}: a wildcard must be `*` or like `*.example.com`")
            return hosts
        return value

    @field_validator("store_url")
    @classmethod
    def _store_location(cls, url: str) -> str:
        from app.store.location import resolve_store_url

        return resolve_store_url(url)

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
    def trusted_hosts(self) -> list[str]:
        """The Host names requests may carry (``["*"]``: any)."""
        if self.allowed_hosts is not None:
            return list(self.allowed_hosts)
        hosts = ["localhost", "127.0.0.1", "[::1]"]
        own = _host_name(self.host)
        if own not in hosts and own not in ("0.0.0.0", "[::]", ""):
            hosts.append(own)
        return hosts

    @property
    def auth_required(self) -> bool:
        return bool(self.require_auth) or not is_loopback(self.host)

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 1024 * 1024)

    @property
    def max_whole_bytes(self) -> int:
        return int(min(self.max_whole_mb, self.max_upload_mb) * 1024 * 1024)

    @property
    def max_map_file_bytes(self) -> int:
        """Largest imported map file (JSON, CSV or DCM): 32 bytes a cell of ``max_cells``, at
        least 1 MiB, never over the whole-read limit. It is parsed whole, at some 30 times its
        size, so a file that cannot hold an allowed map is refused before it is read."""
        return min(self.max_whole_bytes, max(1 << 20, MAP_FILE_BYTES_PER_CELL * self.max_cells))

    @property
    def max_json_bytes(self) -> int:
        return int(self.max_json_mb * 1024 * 1024)

    @property
    def max_decompressed_bytes(self) -> int:
        return int(self.max_decompressed_mb * 1024 * 1024)

    @property
    def a2l_cache_dir(self) -> Path:
        """The A2L parse cache: ``cache_dir``, else the user's cache directory."""
        if self.cache_dir is not None:
            return self.cache_dir / "a2l"
        return default_cache_root() / "a2l"

    @property
    def cache_bytes(self) -> int:
        return int(self.cache_mb * 1024 * 1024)

    @property
    def backend(self) -> Literal["sqlite", "postgresql"]:
        return "sqlite" if self.database_url.startswith("sqlite") else "postgresql"


def default_cache_root() -> Path:
    """``$XDG_CACHE_HOME/mapwise``, else ``~/.cache/mapwise`` (the XDG base directory rule)."""
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".cache"
    return base / "mapwise"


def _host_name(host: str) -> str:
    """A Host-header name as Starlette compares it: lower case, IPv6 in brackets."""
    host = host.strip().lower()
    if ":" in host and not host.startswith("["):
        return f"[{host}]"
    return host


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
