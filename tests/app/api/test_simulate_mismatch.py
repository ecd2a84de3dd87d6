"""``POST /api/datasets/simulate`` takes the mismatch level (docs/fidelity.md#mismatch)."""

from __future__ import annotations

import numpy as np
from fastapi.testclient import TestClient

from estimation.scenarios import get_scenario


def _preview_nox(client: TestClient, dataset_id: int) -> np.ndarray:
    preview = client.get(f"/api/datasets/{dataset_id}/preview?points=20000").json()
    return np.array(preview["channels"]["nox_ppm"]["values"], dtype=float)


def test_simulate_defaults_to_nominal_and_takes_none(client: TestClient) -> None:
    """The default is ``nominal`` (off-grid truth); ``none`` is the perfect-model scenario.
    The stored samples are those the library builds at that level."""
    ids = {}
    for level in (None, "none"):
        body = {"scenario": "nox-nedc", "seed": 3, "duration_s": 20.0}
        if level is not None:
            body["mismatch"] = level
        response = client.post("/api/datasets/simulate", json=body)
        assert response.status_code == 201, response.text
        ids[level] = response.json()["id"]
    for level, built in (
        (None, get_scenario("nox-nedc").build(seed=3, duration_s=20.0)),
        ("none", get_scenario("nox-nedc").build(seed=3, duration_s=20.0, mismatch="none")),
    ):
        stored = _preview_nox(client, ids[level])
        np.testing.assert_allclose(stored, built.signals["nox_ppm"])
    assert not np.array_equal(_preview_nox(client, ids[None]), _preview_nox(client, ids["none"]))


def test_unknown_mismatch_level_is_refused_naming_the_field(client: TestClient) -> None:
    response = client.post(
        "/api/datasets/simulate",
        json={"scenario": "skf-sim1", "duration_s": 5, "mismatch": "mild"},
    )
    assert response.status_code == 422, response.text
    assert response.json()["error"]["field"] == "mismatch"
