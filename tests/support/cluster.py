"""A real Dask cluster for the scale-out tests: ``dask scheduler`` and workers as local
processes (each worker under its nanny, as deployed), the topology of docker-compose.yml."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tests.support.server import ROOT, free_port

DASK = str(Path(sys.executable).with_name("dask"))


class DaskCluster:
    def __init__(self, workers: int = 2) -> None:
        self.port = free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.log = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed in stop()
            "w+", prefix="mapwise-dask-", suffix=".log", delete=False
        )
        env = os.environ | {"DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
        common = {"cwd": ROOT, "stdout": self.log, "stderr": subprocess.STDOUT, "env": env}
        self.scheduler = subprocess.Popen(
            [DASK, "scheduler", "--host", "127.0.0.1", "--port", str(self.port), "--no-dashboard"],
            start_new_session=True,
            **common,  # type: ignore[arg-type]
        )
        worker = [DASK, "worker", self.address, "--nthreads", "1", "--nworkers", "1"]
        worker += ["--memory-limit", "0", "--no-dashboard"]
        self.workers = [
            subprocess.Popen(
                [*worker, "--name", f"w{i}"],
                start_new_session=True,
                **common,  # type: ignore[arg-type]
            )
            for i in range(workers)
        ]
        self.wait_for_workers(workers)

    def client(self):  # type: ignore[no-untyped-def]
        from distributed import Client

        return Client(self.address, set_as_default=False, timeout=30)

    def wait_for_workers(self, n: int, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                with self.client() as c:
                    c.wait_for_workers(n, timeout=max(1.0, deadline - time.monotonic()))
                    return
            except OSError as exc:
                if time.monotonic() > deadline:
                    message = f"no Dask cluster at {self.address}: {self.output()}"
                    raise RuntimeError(message) from exc
                time.sleep(0.5)

    def worker_pids(self) -> dict[str, int]:
        """Dask worker address → pid of the worker process (not its nanny)."""
        with self.client() as c:
            return c.run(os.getpid)

    def worker_running(self, key_prefix: str, timeout: float = 60.0) -> str:
        """The address of the worker executing the task whose key starts with ``key_prefix``."""
        deadline = time.monotonic() + timeout
        with self.client() as c:
            while time.monotonic() < deadline:
                for address, keys in c.processing().items():
                    if any(str(k).startswith(key_prefix) for k in keys):
                        return address
                time.sleep(0.05)
        raise AssertionError(f"no worker is executing {key_prefix}: {self.output()}")

    def output(self) -> str:
        self.log.flush()
        return Path(self.log.name).read_text()[-3000:]

    def stop(self) -> None:
        for proc in [*self.workers, self.scheduler]:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in [*self.workers, self.scheduler]:
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
        self.log.close()
