"""A decimated series keeps a single-sample spike, in the browser against a real server
(issue 18, "plots that keep extremes"): a log of many more samples than the run view's 4000
plot points, with one sample of 64.7 ppm among values of 1–5 ppm, goes through a real run,
and the run view's time plot (the Plotly trace data read from the page) still holds 64.7.
The series are thinned by min/max per bucket (app/runs/results.py, docs/dashboard.md), not
by a stride, which would keep one sample in five here and lose it."""

from __future__ import annotations

import numpy as np
from playwright.sync_api import Page, expect

from tests.frontend.browser import plot_data, wait_run
from tests.support.helpers import spiky_log

N = 20_000  # five samples per bucket of the run view's 4000 points
SPIKE_AT = 12_347
SPIKE = 64.7
# A live frame carries series as float32 (binary frames, docs/rest-api.md), so 64.7 arrives
# as the float32 nearest to it; the stored series that replace them when the page learns the
# run is done come as JSON doubles. Either exact value must be in the trace, whichever the
# page shows when it is read.
SPIKE_VALUES = (SPIKE, float(np.float32(SPIKE)))
TABLE = {
    "axes": [
        {"name": "u1", "breakpoints": [400, 1200, 2000, 2800, 3600]},
        {"name": "u2", "breakpoints": [-5, 15, 35, 65]},
    ]
}


def test_the_run_view_plot_keeps_a_single_sample_spike(page: Page, api) -> None:
    up = api.post(
        "/api/datasets",
        files={"file": ("spike.csv", spiky_log(N, SPIKE_AT, SPIKE, 100.0).encode(), "text/csv")},
        data={"name": "one spike"},
    )
    assert up.status_code == 201, up.text
    body = {
        "dataset_id": up.json()["id"],
        "estimator": "kf",
        "signals": {"y": "y"},
        "table": TABLE,
        "config": {"sigma_w": 0.01, "sigma_v": 0.05, "p0": 10.0},
    }
    created = api.post("/api/runs", json=body)
    assert created.status_code == 201, created.text
    run = wait_run(api, created.json()["id"])
    assert run["status"] == "succeeded", run["error"]

    page.goto(f"/runs/{run['id']}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("succeeded")
    page.wait_for_function(
        "() => (document.querySelector('[data-plot=\"residual\"]')?.data || [])"
        ".some(t => (t.y || []).length > 0)"
    )
    traces = [t for t in plot_data(page, '[data-plot="residual"]') if t["y"]]
    lengths = [len(t["y"]) for t in traces]
    assert all(n < N for n in lengths), lengths  # thinned, not every sample
    measured = [t for t in traces if max((v for v in t["y"] if v is not None), default=0) > 10]
    assert measured, [(t["name"], max(v for v in t["y"] if v is not None)) for t in traces]

    def spike_in(y: list) -> float | None:
        return next((v for v in SPIKE_VALUES if v in y), None)

    assert any(spike_in(t["y"]) for t in measured), [(t["name"], max(t["y"])) for t in measured]
    peak = next(t for t in measured if spike_in(t["y"]))
    assert peak["name"] == "measured"
    t_peak = peak["x"][peak["y"].index(spike_in(peak["y"]))]
    assert abs(t_peak - SPIKE_AT / 100.0) <= 2 * N / 4000 / 100.0  # within a bucket
    rest = sorted(v for v in peak["y"] if v is not None)
    assert rest[-2] < 6.0  # one spike, not a smear
