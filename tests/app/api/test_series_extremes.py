"""A one-sample spike survives every thinning between the worker and the plots: 200 000
samples of a small signal with one sample of 64.7 go through a real run; the stored series
(``series_points`` = 4000 of them), REST ``/runs/{id}/series`` at the run view's 4000 and the
Compare view's 1500 points, and the stream's full frame of the finished run all still hold
it (min/max per bucket, not a stride)."""

from __future__ import annotations

import numpy as np
from fastapi.testclient import TestClient

from tests.support.helpers import spiky_log, start_run, upload_ok, wait_run
from tests.support.server import run_body

N = 200_000
SPIKE_AT = 123_457
SPIKE = 64.7


def test_a_single_sample_spike_reaches_every_plot(client: TestClient) -> None:
    dataset = upload_ok(client, spiky_log(N, SPIKE_AT, SPIKE, 1000.0))
    done = wait_run(client, start_run(client, run_body(dataset["id"], "kf"))["id"], timeout=300)
    assert done["status"] == "succeeded", done["error"]

    for points in (4000, 1500):  # the run view's request, the Compare view's
        body = client.get(f"/api/runs/{done['id']}/series", params={"points": points}).json()
        assert len(body["time"]) == points
        measured = np.array(body["series"]["measured"]["values"], dtype=float)
        assert measured.max() == SPIKE
        assert np.sort(measured)[-2] < 6.0  # the rest stays small: one spike, not a smear
        t_peak = body["time"][int(measured.argmax())]
        assert abs(t_peak - SPIKE_AT / 1000.0) <= 2 * N / points / 1000.0  # within a bucket
        residual = np.array(body["series"]["residual"]["values"], dtype=float)
        assert np.nanmax(np.abs(residual)) > 50.0

    with client.websocket_connect(f"/api/runs/{done['id']}/stream") as ws:
        frame = ws.receive_json()
    assert frame["type"] == "full"
    assert max(frame["series"]["measured"]["values"]) == SPIKE
