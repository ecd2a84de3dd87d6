"""The live frames of a run, typed: what a worker publishes and what a viewer receives.

A worker publishes *messages* to the hub (``kind``: ``start``, ``tick``, ``status``; plain
dicts on the way, so they cross a process queue or Dask's event log). The hub and the
WebSocket route send *frames* to viewers (``type``: ``full``, ``delta``, ``status``,
``error``). Every frame here builds its JSON document with ``to_json()``; the keys are the
contract the dashboard and external scripts read (README "Live stream"), pinned by
``tests/app/runs/test_frames.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from app.domain import Series
from app.io.decimate import finite_or_none

Json = dict[str, Any]


def _empty_trajectory() -> Json:
    return {"time": [], "points": []}


# --- worker → hub ----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class StartMessage:
    """The run's first chunk is done: the grid, the length and every series' unit and role."""

    run_id: int
    axes: list[Json] | None = None
    n_samples: int = 0
    trajectory_channels: list[str] = field(default_factory=list)
    units: dict[str, str] = field(default_factory=dict)
    roles: dict[str, str] = field(default_factory=dict)

    def to_json(self) -> Json:
        return {
            "kind": "start",
            "run_id": self.run_id,
            "axes": self.axes,
            "n_samples": self.n_samples,
            "trajectory_channels": self.trajectory_channels,
            "units": self.units,
            "roles": self.roles,
        }

    @classmethod
    def from_json(cls, doc: Json) -> StartMessage:
        return cls(
            run_id=int(doc["run_id"]),
            axes=doc.get("axes"),
            n_samples=int(doc.get("n_samples", 0)),
            trajectory_channels=list(doc.get("trajectory_channels", [])),
            units=dict(doc.get("units", {})),
            roles=dict(doc.get("roles", {})),
        )


@dataclass(frozen=True, slots=True)
class TickMessage:
    """The samples since the previous tick (decimated) and the current map and metrics.

    ``seq`` counts ticks from 1 (a gap tells the hub a tick was lost); ``emitted_at`` is the
    wall clock (s since the epoch) for frame-delay figures; ``series`` maps a series key to
    ``{"time": [...], "values": [...]}`` (NaN as ``None``).
    """

    run_id: int
    seq: int
    sample: int
    n_samples: int
    progress: float
    time_s: float | None = None
    emitted_at: float | None = None
    values: Any = None
    variances: Any = None
    visits: Any = None
    active_cell: list[int] | None = None
    trajectory: Json = field(default_factory=_empty_trajectory)
    series: dict[str, Json] = field(default_factory=dict)
    metrics: dict[str, float | None] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)

    def to_json(self) -> Json:
        return {"kind": "tick", "run_id": self.run_id, "seq": self.seq} | self._body()

    def delta(self) -> DeltaFrame:
        return DeltaFrame(self)

    def _body(self) -> Json:
        return {
            "sample": self.sample,
            "n_samples": self.n_samples,
            "progress": self.progress,
            "time_s": self.time_s,
            "emitted_at": self.emitted_at,
            "values": self.values,
            "variances": self.variances,
            "visits": self.visits,
            "active_cell": self.active_cell,
            "trajectory": self.trajectory,
            "series": self.series,
            "metrics": self.metrics,
            "rejected": self.rejected,
        }

    @classmethod
    def from_json(cls, doc: Json) -> TickMessage:
        return cls(
            run_id=int(doc["run_id"]),
            seq=int(doc["seq"]),
            sample=int(doc["sample"]),
            n_samples=int(doc.get("n_samples", 0)),
            progress=float(doc["progress"]),
            time_s=doc.get("time_s"),
            emitted_at=doc.get("emitted_at"),
            values=doc.get("values"),
            variances=doc.get("variances"),
            visits=doc.get("visits"),
            active_cell=doc.get("active_cell"),
            trajectory=doc.get("trajectory") or _empty_trajectory(),
            series=doc.get("series") or {},
            metrics=doc.get("metrics") or {},
            rejected=doc.get("rejected") or {},
        )


@dataclass(frozen=True, slots=True)
class StatusFrame:
    """A status change: published by a worker (``to_message``), sent to viewers (``to_json``)."""

    run_id: int
    status: str
    error: str | None = None
    progress: float = 0.0

    def to_message(self) -> Json:
        return {
            "kind": "status",
            "run_id": self.run_id,
            "status": str(self.status),
            "error": self.error,
            "progress": self.progress,
        }

    def to_json(self) -> Json:
        return {
            "type": "status",
            "status": str(self.status),
            "error": self.error,
            "progress": self.progress,
        }

    @classmethod
    def from_json(cls, doc: Json) -> StatusFrame:
        return cls(
            run_id=int(doc["run_id"]),
            status=str(doc["status"]),
            error=doc.get("error"),
            progress=float(doc.get("progress", 0.0)),
        )


Message = StartMessage | TickMessage | StatusFrame
_MESSAGES: dict[str, Any] = {"start": StartMessage, "tick": TickMessage, "status": StatusFrame}


def parse_message(doc: Json) -> Message | None:
    """A worker message from its dict (``None`` for an unknown kind)."""
    kind = _MESSAGES.get(str(doc.get("kind")))
    return None if kind is None else kind.from_json(doc)


# --- hub / stream → viewer -------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class DeltaFrame:
    """A tick as viewers get it: its new points and the current map (no run id, no seq)."""

    tick: TickMessage

    def to_json(self) -> Json:
        body = self.tick._body()
        del body["n_samples"]
        return {"type": "delta"} | body


@dataclass(frozen=True, slots=True)
class FullFrame:
    """Everything a viewer needs to draw the run from scratch: the run document (as
    ``GET /api/runs/{id}``), the map, trajectory and series so far (series: key →
    ``{"unit", "role", "time", "values"}``), metrics and rejections."""

    run: Json
    axes: list[Json] | None
    values: Any
    variances: Any
    visits: Any
    active_cell: list[int] | None
    trajectory: Json
    series: dict[str, Json]
    metrics: dict[str, Any]
    rejected: dict[str, int]
    sample: int
    n_samples: int

    def to_json(self) -> Json:
        return {
            "type": "full",
            "run": self.run,
            "axes": self.axes,
            "values": self.values,
            "variances": self.variances,
            "visits": self.visits,
            "active_cell": self.active_cell,
            "trajectory": self.trajectory,
            "series": self.series,
            "metrics": self.metrics,
            "rejected": self.rejected,
            "sample": self.sample,
            "n_samples": self.n_samples,
        }

    def status(self) -> StatusFrame:
        """The status frame that follows a finished run's full frame."""
        return StatusFrame(
            run_id=int(self.run["id"]),
            status=self.run["status"],
            error=self.run["error"],
            progress=self.run["progress"],
        )


def series_line(series: Series) -> Json:
    """A stored series as a full frame carries it (NaN as ``None``)."""
    return {
        "unit": series.unit,
        "role": None if series.role is None else str(series.role),
        "time": finite_or_none(series.time),
        "values": finite_or_none(series.values),
    }


@dataclass(frozen=True, slots=True)
class ErrorFrame:
    """The stream cannot start (e.g. no such run); ``error`` is the REST error body."""

    error: Json

    def to_json(self) -> Json:
        return {"type": "error", "error": self.error}
