"""The map document: the JSON a finished map estimate is written as.

``mapwise adapt`` and ``mapwise run`` print it, the service exports a run's map version as
it (``GET /api/runs/{id}/export?format=json``) and :mod:`app.io.map_import` reads it back.
It is a contract used by scripts outside the repository::

    {"estimator", "axes": [{"name", "unit", "breakpoints"}], "values", "variance",
     "samples", "rejected": {reason: count}, "timing": {"load_s", "estimate_s"}}

``timing.warmup_s`` (``mapwise adapt``) is the one-off numba start of a new process, timed
apart from ``estimate_s`` by a warm-up fit of the log's first samples.

``values`` and ``variance`` are nested lists in axis order (``variance`` is ``null`` for the
covariance-free filters). Extra keys (``output``, ``accepted``, ``config``) may be added;
existing ones never change.
"""

from __future__ import annotations

from typing import Any

from estimation.estimator import Snapshot


def map_document(
    snapshot: Snapshot,
    *,
    samples: int,
    load_s: float | None = None,
    estimate_s: float,
    warmup_s: float | None = None,
    quantity: str = "",
    unit: str = "",
) -> dict[str, Any]:
    """The map document of a final snapshot (``timing.load_s`` and ``timing.warmup_s`` only
    when given): what the map holds, ``quantity`` in ``unit`` (a table filter's output
    column and its unit, the LPV and ekf-map quantity), then the map and its counts."""
    table = snapshot.table
    assert table is not None
    rejected = {k: int(v) for k, v in snapshot.rejected.items()}
    timing = {"estimate_s": estimate_s}
    if load_s is not None:
        timing = {"load_s": load_s} | timing
    if warmup_s is not None:
        timing["warmup_s"] = warmup_s
    return {
        "estimator": snapshot.estimator,
        "quantity": quantity,
        "unit": unit,
        "axes": [a.to_dict() for a in table.axes],
        "values": table.values.tolist(),
        "variance": None if snapshot.variance is None else snapshot.variance.tolist(),
        "samples": samples,
        "accepted": samples - sum(rejected.values()),
        "rejected": rejected,
        "timing": timing,
    }
