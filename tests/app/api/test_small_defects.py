"""Small server-side defects of issue 18 (item 6): unknown addresses, ``HEAD /``, and a CSV
log without a time column."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from tests.support.helpers import log_csv, run_body, start_run, upload_ok, wait_run


@pytest.mark.parametrize("path", ["/nope", "/runs/abc", "/datasets/7/extra", "/a/b/c.txt"])
def test_unknown_page_addresses_get_the_dashboard(client: TestClient, path: str) -> None:
    """A mistyped address in the browser gets the dashboard page (its router shows "Page not
    found"), not a JSON error."""
    response = client.get(path)
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/html")
    assert '<script type="importmap">' in response.text
    head = client.head(path)
    assert head.status_code == 200
    assert head.headers["content-type"].startswith("text/html")


@pytest.mark.parametrize("path", ["/api/nope", "/api/runs/1/nope", "/api"])
def test_unknown_api_paths_stay_json_404(client: TestClient, path: str) -> None:
    response = client.get(path)
    assert response.status_code == 404
    assert response.headers["content-type"].startswith("application/json")
    assert response.json()["error"]["code"] == "not_found"


def test_unknown_static_files_and_other_methods_are_not_the_page(client: TestClient) -> None:
    assert client.get("/static/nope.js").status_code == 404
    assert client.post("/nope", json={}).status_code == 404
    assert client.post("/api/nope", json={}).status_code == 404
    # A wrong method on a real API route is still 405, naming the allowed ones.
    wrong = client.put("/api/datasets")
    assert wrong.status_code == 405
    assert "GET" in wrong.headers["allow"]


def test_head_root_is_200_and_get_root_still_redirects(client: TestClient) -> None:
    head = client.head("/")
    assert head.status_code == 200
    assert head.headers["content-type"].startswith("text/html")
    assert client.get("/", follow_redirects=False).status_code == 307
    assert client.head("/datasets").status_code == 200


def test_baselines_credit_their_own_sources_not_the_skf_paper(client: TestClient) -> None:
    """rls and nlms are textbook baselines: the catalog credits Ljung & Söderström / Haykin,
    not Guardiola et al.'s SKF paper (which the kf, skf and sskf still credit)."""
    items = client.get("/api/estimators").json()["items"]
    paper = {e["name"]: e["paper"] for e in items}
    for name in ("rls", "nlms"):
        assert "Guardiola" not in paper[name]
        assert not paper[name].endswith("the SKF paper")
        assert "Haykin" in paper[name]
    assert "Ljung & Söderström (1983)" in paper["rls"]
    assert "normalised LMS" in paper["nlms"]
    for name in ("kf", "skf", "sskf"):
        assert "Guardiola" in paper[name]


@pytest.mark.parametrize("sensor", [None, {"lag": 0.5, "delay_samples": 7}])
def test_rejection_counts_add_up(client: TestClient, sensor: dict | None) -> None:
    """Two overlapping gates and the innovation gate: the estimator's reasons (mask,
    innovation, delay) are disjoint and sum to the total the run view shows, and the gates
    split the mask count exactly, a sample failing both counted once (under the first
    gate) — also with a sensor delay, where a step is masked when its measurement or its
    operating point is gated."""
    dataset = upload_ok(client, log_csv(3000, seed=11))
    gates = [
        {"type": "range", "channel": "temp", "min": 40.0},
        {"type": "range", "channel": "u1", "max": 1500.0},
    ]
    extra = {"sensor": sensor} if sensor else {}
    body = run_body(dataset["id"], gates=gates, gate_sigma=2.0, **extra)
    done = wait_run(client, start_run(client, body)["id"])
    assert done["status"] == "succeeded", done["error"]
    rejected = done["rejected"]
    gate_counts = {k: v for k, v in rejected.items() if k.startswith("gate:")}
    assert set(gate_counts) == {"gate:range:temp", "gate:range:u1"}
    assert all(v > 0 for v in gate_counts.values())
    assert sum(gate_counts.values()) == rejected["mask"]
    if sensor is None:
        assert rejected["innovation"] > 0
    assert rejected.get("delay", 0) == (sensor or {}).get("delay_samples", 0)


NO_TIME = "speed [rpm],nox [ppm]\n" + "".join(f"{1000 + k},{k % 7}\n" for k in range(200))


def test_a_csv_without_time_is_refused_naming_time(client: TestClient) -> None:
    """No time column and no rate: 422 naming ``time`` (never a silent 1 Hz)."""
    r = client.post("/api/datasets", files={"file": ("log.csv", NO_TIME.encode())})
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["field"] == "time"
    assert "no time column" in error["message"]
    assert "rate_hz" in error["message"]


def test_a_csv_without_time_takes_the_given_rate_and_says_so(client: TestClient) -> None:
    r = client.post(
        "/api/datasets",
        files={"file": ("log.csv", NO_TIME.encode())},
        data={"rate_hz": "50", "name": "no-time-50hz"},
    )
    assert r.status_code == 201, r.text
    dataset = r.json()
    assert dataset["rate_hz"] == pytest.approx(50.0)
    assert dataset["duration_s"] == pytest.approx(199 / 50)
    assert dataset["time_column"] == ""
    assert any("given rate of 50 Hz" in n for n in dataset["notes"])
    again = client.get(f"/api/datasets/{dataset['id']}").json()
    assert again["notes"] == dataset["notes"]


@pytest.mark.parametrize("rate", ["0", "-5", "nan", "inf", "fast"])
def test_a_bad_rate_is_refused_naming_rate_hz(client: TestClient, rate: str) -> None:
    r = client.post(
        "/api/datasets", files={"file": ("log.csv", NO_TIME.encode())}, data={"rate_hz": rate}
    )
    assert r.status_code == 422, r.text
    assert r.json()["error"]["field"] == "rate_hz"


def test_a_rate_beside_a_time_column_is_refused(client: TestClient) -> None:
    """A file with its own time base and a rate: which one is meant is unclear, so 422."""
    r = client.post(
        "/api/datasets",
        files={"file": ("log.csv", log_csv(100).encode())},
        data={"rate_hz": "50"},
    )
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["field"] == "rate_hz"
    assert "'time'" in error["message"]
