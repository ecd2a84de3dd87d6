"""The NOx sensor model of SKF §6 that ``mapwise reproduce`` scores learnt maps with:
SKF (23)–(25), a delay τ and a lag a after the table, and SKF (35)'s error ``e_M``."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from estimation.kernels.sensor import sensor_kernel
from estimation.scenarios import ScenarioData, get_scenario
from estimation.signals import delay_samples
from estimation.table import Table as MapTable


class SensorModel:
    """SKF (23)–(25) with the scenario's sensor settings: ``y_M = (1−a)/(1−a z⁻¹) T(u_{k−τ})``."""

    def __init__(self, data: ScenarioData) -> None:
        assert data.true_map is not None
        sensor = get_scenario(data.scenario).default_config("skf")["sensor"]
        self.lag = float(sensor["lag"])
        self.delay = delay_samples(float(sensor["delay_s"]), data.signals.sample_period())
        idx, w = data.true_map.regressor(data.scoring_points())
        n, corners = idx.shape
        rows = np.repeat(np.arange(n), corners)
        self.psi = sp.csr_matrix((w.ravel(), (rows, idx.ravel())), shape=(n, data.true_map.size))
        self.measured = data.signals[data.map_output or "nox_ppm"]

    def predict(self, table: MapTable) -> np.ndarray:
        """(n,) sensor signal predicted with ``table`` [ppm]."""
        x = np.ascontiguousarray(self.psi @ table.flat)
        out = np.empty_like(x)
        sensor_kernel(x, self.delay, self.lag, float(x[0]), out)
        return out

    def e_m(self, tables: Sequence[MapTable], *, block: int = 32) -> np.ndarray:
        """SKF (35) over the whole cycle, after the delay has filled, per table [ppm]."""
        out = np.empty(len(tables))
        y = np.empty(self.measured.size)
        for start in range(0, len(tables), block):
            chunk = tables[start : start + block]
            x = np.asarray(self.psi @ np.stack([t.flat for t in chunk], axis=1)).T.copy()
            for j, row in enumerate(x):
                sensor_kernel(row, self.delay, self.lag, float(row[0]), y)
                out[start + j] = np.mean(np.abs(self.measured - y)[self.delay :])
        return out
