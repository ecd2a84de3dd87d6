"""A simulated dataset's truth blob, and the npz samples of datasets before revision 0008.

The truth (true map, scoring points, true series) stays in the dataset's row and feeds the
run metrics. The samples live in the artifact store since revision 0008 (:mod:`app.store`);
:func:`pack_signals` is the layout of the ``payload`` blobs that revision moves there
(``time`` plus ``c0``, ``c1`` … in the channels' order) and its downgrade writes back.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from app.db import blobs
from estimation.scenarios import ScenarioData
from estimation.signals import Signals
from estimation.table import Table


def pack_signals(signals: Signals) -> bytes:
    arrays = {"time": signals.time}
    arrays |= {f"c{i}": signals[name] for i, name in enumerate(signals.names)}
    return blobs.pack(arrays)


@dataclass(frozen=True, slots=True)
class Truth:
    """What a simulated dataset knows that a log does not (see :class:`ScenarioData`)."""

    true_map: Table | None
    map_inputs: tuple[str, ...]
    map_output: str | None
    map_points: np.ndarray | None
    scored_series: dict[str, np.ndarray]
    true_along: np.ndarray | None = None
    metadata: dict[str, Any] | None = None

    def scenario_data(self, scenario: str, seed: int, signals: Signals) -> ScenarioData:
        return ScenarioData(
            scenario=scenario,
            seed=seed,
            signals=signals,
            truth={},
            true_map=self.true_map,
            map_inputs=self.map_inputs,
            map_output=self.map_output,
            map_points=self.map_points,
            scored_series=self.scored_series,
            true_along=self.true_along,
            metadata=dict(self.metadata or {}),
        )


def pack_truth(data: ScenarioData) -> bytes:
    names = list(data.scored_series)
    true_map = data.true_map
    meta: dict[str, Any] = {
        "true_map_axes": None if true_map is None else [a.to_dict() for a in true_map.axes],
        "map_inputs": list(data.map_inputs),
        "map_output": data.map_output,
        "scored": names,
        "metadata": data.metadata,
        "estimator_params": data.estimator_params,
    }
    arrays: dict[str, np.ndarray] = {f"s{i}": data.scored_series[n] for i, n in enumerate(names)}
    if data.true_map is not None:
        arrays["true_map"] = data.true_map.values
        arrays["map_points"] = data.scoring_points()
    if data.true_along is not None:
        arrays["true_along"] = data.true_along
    return blobs.pack_meta(arrays, meta)


def unpack_truth(blob: bytes) -> Truth:
    arrays, meta = blobs.unpack_meta(blob)
    true_map = None
    if meta["true_map_axes"] is not None:
        true_map = Table.from_dict({"axes": meta["true_map_axes"], "values": arrays["true_map"]})
    return Truth(
        true_map=true_map,
        map_inputs=tuple(meta["map_inputs"]),
        map_output=meta["map_output"],
        map_points=arrays.get("map_points"),
        scored_series={n: arrays[f"s{i}"] for i, n in enumerate(meta["scored"])},
        true_along=arrays.get("true_along"),
        metadata=meta.get("metadata"),
    )
