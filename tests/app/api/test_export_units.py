"""Units in a run's exports: the map file of an ``lpv`` or ``ekf-map`` run names the map's
quantity and unit (:func:`app.services.truth_map.map_quantity`, the one source the run view
also reads) in its CSV header, DCM ``EINHEIT_W`` and JSON document, and the series CSV gives
each estimator output the unit its registry spec declares (``output_units``)."""

from __future__ import annotations

import csv
import io
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from estimation.registry import get_spec
from estimation.scenarios import get_scenario
from tests.support.helpers import start_run, upload_ok, wait_run


def _scenario_csv(scenario: str, seed: int, duration_s: float) -> tuple[str, dict[str, Any]]:
    """A realisation of ``scenario`` as an uploaded log (every channel with its unit) and the
    scenario's estimator configs."""
    sc = get_scenario(scenario)
    data = sc.build(seed=seed, duration_s=duration_s)
    s = data.signals
    header = ["time [s]"] + [f"{c} [{s.units[c]}]" if s.units.get(c) else c for c in s.names]
    columns = np.column_stack([s.time] + [s[c] for c in s.names])
    rows = [",".join(header)] + [",".join(repr(float(v)) for v in row) for row in columns]
    return "\n".join(rows) + "\n", {e: sc.default_config(e, data) for e in sc.suggested}


@pytest.fixture(scope="module")
def runs(client: TestClient) -> dict[str, dict[str, Any]]:
    """A finished ``lpv`` run on ``maf-whtc`` and ``ekf-map`` run on ``maf-1d-whtc``."""
    done = {}
    for scenario, estimator in (("maf-whtc", "lpv"), ("maf-1d-whtc", "ekf-map")):
        text, configs = _scenario_csv(scenario, seed=7, duration_s=30.0)
        dataset = upload_ok(client, text)
        body = {"dataset_id": dataset["id"], "estimator": estimator, "signals": {}}
        run = wait_run(client, start_run(client, body | {"config": configs[estimator]})["id"])
        assert run["status"] == "succeeded", run["error"]
        done[estimator] = run
    return done


@pytest.mark.parametrize(
    ("estimator", "quantity", "unit"),
    [("lpv", "maf_error_kg_s", "kg/s"), ("ekf-map", "maf_q", "-")],
)
def test_map_exports_carry_the_map_quantity_and_unit(
    client: TestClient, runs, estimator: str, quantity: str, unit: str
) -> None:
    url = f"/api/runs/{runs[estimator]['id']}/export"
    text = client.get(url, params={"format": "csv", "part": "map"})
    assert text.status_code == 200, text.text
    header = next(csv.reader(io.StringIO(text.text)))
    if " \\ " not in header[0]:  # a 2-D grid's corner holds its two axes
        assert f"{quantity} [{unit}]" in header, header

    dcm = client.get(url, params={"format": "dcm"})
    assert dcm.status_code == 200, dcm.text
    assert quantity.upper() in dcm.text
    assert f'EINHEIT_W "{unit}"' in dcm.text, dcm.text[:600]

    document = client.get(url, params={"format": "json"}).json()
    assert (document["quantity"], document["unit"]) == (quantity, unit)


@pytest.mark.parametrize("estimator", ["lpv", "ekf-map"])
def test_series_csv_gives_estimator_outputs_their_units(
    client: TestClient, runs, estimator: str
) -> None:
    reply = client.get(
        f"/api/runs/{runs[estimator]['id']}/export", params={"format": "csv", "part": "series"}
    )
    assert reply.status_code == 200, reply.text
    header = next(csv.reader(io.StringIO(reply.text)))
    declared = {n: u for n, u in get_spec(estimator).output_units.items() if u}
    found = 0
    for name, unit in declared.items():
        columns = [h for h in header if h.split(" [")[0] in (name, f"output:{name}")]
        for column in columns:
            assert column.endswith(f"[{unit}]"), (column, unit)
            found += 1
    assert found >= 2, header
