"""The API process never loads what only the runs need (docs/reliability.md#api-memory): a
real ``mapwise serve`` that seeds its demo, answers the catalog, takes uploads (streamed,
small CSVs read whole, MDF4 and MCAP logs), simulates scenarios (streamed and plain), plans
and follows runs and serves their versions, series, exports and true map has mapped none of
numba's, llvmlite's, pandas's or asammdf's shared libraries (about 120, 45 and 10 MiB of its
memory otherwise). The runs execute in the worker processes, and the simulations and the
MDF4 and MCAP reads in the dataset child, which do load them.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest

from tests.support.helpers import log_csv, start_run, upload_ok, wait_run
from tests.support.server import Server, run_body

pytestmark = pytest.mark.slow  # a real server, its demo run and its workers

HEAVY = ("numba", "llvmlite", "pandas", "asammdf")


def _libraries(pid: int, packages: tuple[str, ...] = HEAVY) -> set[str]:
    """The files of ``packages`` mapped into process ``pid``."""
    mapped = (line.split()[-1] for line in Path(f"/proc/{pid}/maps").read_text().splitlines())
    return {path for path in mapped if any(f"/{name}/" in path for name in packages)}


def _mdf4(path: Path) -> bytes:
    from asammdf import MDF, Signal

    t = np.arange(2000) * 0.01
    mdf = MDF(version="4.10")
    mdf.append([Signal(np.sin(t), t, name="rpm", unit="1/min")])
    mdf.save(path, overwrite=True)
    return path.read_bytes()


def _mcap() -> bytes:
    from mcap.writer import Writer

    buffer = io.BytesIO()
    writer = Writer(buffer)
    writer.start()
    schema = {"type": "object", "properties": {"t": {"type": "number"}, "x": {"type": "number"}}}
    schema_id = writer.register_schema("s", "jsonschema", json.dumps(schema).encode())
    channel = writer.register_channel("/s", "json", schema_id)
    for k in range(500):
        data = json.dumps({"t": k * 0.01, "x": k * 0.5}).encode()
        writer.add_message(channel, log_time=k * 10**7, data=data, publish_time=k * 10**7)
    writer.finish()
    return buffer.getvalue()


def test_the_api_process_serves_a_run_without_numba_or_pandas(tmp_path: Path) -> None:
    server = Server(f"sqlite:///{tmp_path / 'api.db'}", demo=True, workers=1)
    try:
        client = server.http
        assert client.get("/api/estimators").status_code == 200
        assert client.get("/api/scenarios").status_code == 200
        dataset = upload_ok(client, log_csv(4000))  # read whole
        big = log_csv(220_000)  # over the 16 MiB from which an upload streams
        assert len(big) > 16 << 20
        upload_ok(client, big)
        assert upload_ok(client, _mdf4(tmp_path / "log.mf4"), "log.mf4")["source"] == "mdf4"
        assert upload_ok(client, _mcap(), "log.mcap")["source"] == "mcap"
        run = start_run(client, run_body(dataset["id"], "skf"))
        assert wait_run(client, run["id"])["status"] == "succeeded"
        for path in ("versions", "series", "cells"):
            assert client.get(f"/api/runs/{run['id']}/{path}").status_code == 200, path
        for format in ("json", "csv", "dcm", "mcap"):
            response = client.get(f"/api/runs/{run['id']}/export", params={"format": format})
            assert response.status_code == 200, (format, response.text[:200])

        simulated = client.post(
            "/api/datasets/simulate", json={"scenario": "skf-sim2", "duration_s": 20.0}
        )
        assert simulated.status_code == 201, simulated.text
        with client.stream(
            "POST", "/api/datasets/simulate/stream", json={"scenario": "maf-1d-whtc", "seed": 2}
        ) as streamed:
            assert '"dataset"' in "".join(streamed.iter_text()).splitlines()[-1]
        truth_run = start_run(client, run_body(simulated.json()["id"]))  # the true map's grid
        assert wait_run(client, truth_run["id"])["status"] == "succeeded"
        truth = client.get(f"/api/runs/{truth_run['id']}/truth-map")
        assert truth.status_code == 200, truth.text
        assert truth.json()["values"] is not None

        assert _libraries(server.process.pid) == set()
        child = server.dataset_child()
        assert child is not None
        assert _libraries(child, ("numba",))  # it simulated
        assert _libraries(child, ("asammdf",))  # it read the MDF4 log
        workers = server.workers()
        assert workers
        assert all(_libraries(pid, ("numba",)) for pid in workers)
        assert all(_libraries(pid, ("pandas",)) == set() for pid in workers)
    finally:
        server.stop()
