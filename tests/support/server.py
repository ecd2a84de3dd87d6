"""A real ``mapwise serve`` (uvicorn) in a subprocess, and what its clients share: a free port
and the body of a run request. Used by the real-process tests (WebSocket, kill, load, Dask),
the browser tests (tests/frontend/browser.py) and the scripts that start a server
(scripts/load.py, bench_service.py, bench_scaleout.py, screenshot.py, bench_dashboard.py),
which put the repository root on ``sys.path`` to import it. It needs only httpx and psutil.
"""

from __future__ import annotations

import hashlib
import os
import random
import signal
import socket
import ssl
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import psutil

ROOT = Path(__file__).resolve().parents[2]
U1 = [500.0, 1500.0, 2500.0, 3500.0]
U2 = [0.0, 20.0, 40.0, 60.0]
TABLE = {"axes": [{"name": "u1", "breakpoints": U1}, {"name": "u2", "breakpoints": U2}]}
FINISHED = ("succeeded", "failed", "cancelled", "interrupted")
PORT_ATTEMPTS = 5
DATASET_CHILD = "mw-datasets"  # app.services.dataset_child.PROCESS_NAME (this imports no app)
WORKER_NAMES = ("mw-idle", "mw-run-")  # what a run worker calls itself (app/runs/pool.py)


# The servers speak plain HTTP, but every httpx.Client builds a TLS context and loads the CA
# bundle (about 20 ms of CPU) unless it is given one: the suite's clients share this one.
TLS = ssl.create_default_context()


class PortTakenError(RuntimeError):
    """The server could not bind its port: another process took it after :func:`free_port`."""


# Ports handed out by free_port: below Linux's ephemeral range (32768-60999 by default), so no
# outgoing connection (a browser's, a database client's) can take one, split into one slice per
# pytest-xdist worker ("gw0", "gw1", …; "" outside xdist), so two workers never pick the same.
PORTS_LOW, PORTS_HIGH, PORTS_PER_WORKER = 20000, 32000, 1000


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now, from this process's slice of ``PORTS_LOW`` …
    ``PORTS_HIGH`` (a random one that binds; a server binds it right after, and
    :class:`Server` retries with another if something took it meanwhile)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    slices = (PORTS_HIGH - PORTS_LOW) // PORTS_PER_WORKER
    index = int(worker[2:]) + 1 if worker.startswith("gw") else 0
    low = PORTS_LOW + (index % slices) * PORTS_PER_WORKER
    for port in random.sample(range(low, low + PORTS_PER_WORKER), PORTS_PER_WORKER):
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise RuntimeError(f"no free port in {low}-{low + PORTS_PER_WORKER - 1}")


def run_body(
    dataset_id: int,
    estimator: str = "skf",
    *,
    signals: dict[str, str] | None = None,
    table: dict[str, Any] | None = None,
    **config: Any,
) -> dict[str, Any]:
    """A ``POST /api/runs`` body: the estimator on output ``y`` over the 4×4 ``u1``×``u2``
    table by default; the Kalman filters get small default noises that ``config`` overrides."""
    base = {"sigma_w": 0.01, "sigma_v": 0.05, "p0": 10.0} if estimator in ("kf", "skf") else {}
    return {
        "dataset_id": dataset_id,
        "estimator": estimator,
        "signals": {"y": "y"} if signals is None else signals,
        "table": TABLE if table is None else table,
        "config": base | config,
    }


def store_for(database_url: str) -> str:
    """The artifact store of a server on ``database_url``: its own directory (a restarted
    server on the same database finds its datasets) under ``MAPWISE_STORE_URL`` (the test
    session's, tests/conftest.py), else under the system's temporary directory; never the
    repository's ``./mapwise-data/``."""
    digest = hashlib.sha256(database_url.encode()).hexdigest()[:12]
    base = os.environ.get("MAPWISE_STORE_URL") or str(
        Path(tempfile.gettempdir()) / "mapwise-stores"
    )
    return f"{base.rstrip('/')}/{digest}"


class Server:
    """``python -m app.cli serve`` on a free port; ``kill()`` is ``kill -9``.

    ``env`` adds to the inherited environment, from which ``MAPWISE_REQUIRE_AUTH`` is dropped
    (a developer's shell must not lock the tests out) and to which ``MAPWISE_STORE_URL`` is
    set to :func:`store_for` the database; the server's output goes to a
    temporary log, :meth:`output` gives its tail and :meth:`stop` deletes it."""

    def __init__(
        self,
        database_url: str,
        *,
        demo: bool = False,
        workers: int | None = 2,
        log_level: str = "warning",
        env: dict[str, str] | None = None,
    ) -> None:
        self.database_url = database_url
        self.args = [
            sys.executable, "-m", "app.cli", "serve", "--host", "127.0.0.1",
            "--database-url", database_url, "--log-level", log_level,
        ]  # fmt: skip
        if workers is not None:  # None: the app's default (one per core, 2 to 8)
            self.args += ["--workers", str(workers)]
        if not demo:
            self.args.append("--no-demo")
        inherited = {k: v for k, v in os.environ.items() if k != "MAPWISE_REQUIRE_AUTH"}
        defaults = {"MAPWISE_CANCEL_POLL_S": "0.05", "PYTHONUNBUFFERED": "1"}
        self.env = inherited | defaults | {"MAPWISE_STORE_URL": store_for(database_url)}
        self.env |= env or {}
        self._last_output = ""
        for attempt in range(1, PORT_ATTEMPTS + 1):
            self._start()
            try:
                self._wait_ready()
                return
            except PortTakenError:
                self.stop()
                if attempt == PORT_ATTEMPTS:
                    raise
            except BaseException:
                self.stop()
                raise

    def _start(self) -> None:
        """Start the server on a new free port, its output to a new temporary log."""
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.ws_base = f"ws://127.0.0.1:{self.port}"
        self.log = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed in stop()
            "w+", prefix="mapwise-serve-", suffix=".log", delete=False
        )
        self.process = subprocess.Popen(
            [*self.args, "--port", str(self.port)], cwd=ROOT, env=self.env, stdout=self.log,
            stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
        self.http = httpx.Client(base_url=self.base, timeout=30, verify=TLS)

    @property
    def url(self) -> str:
        return self.base

    def api(self, timeout: float = 60.0) -> httpx.Client:
        """A new client of the server (the caller closes it), for another thread, say."""
        return httpx.Client(base_url=self.base, timeout=timeout, verify=TLS)

    def _wait_ready(self, timeout: float = 90.0) -> None:
        """Until ``/api/health`` answers from this server's own socket; raises
        :class:`PortTakenError` if another process took the port first."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                output = self.output()
                if "address already in use" in output.lower():
                    raise PortTakenError(f"port {self.port} was taken: {output}")
                raise RuntimeError(f"server exited with {self.process.returncode}: {output}")
            try:
                # A health answer counts only once this server listens on the port: until it
                # binds, another process that took the port may be the one answering.
                if self.http.get("/api/health").status_code == 200 and self._listening():
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.1)
        raise RuntimeError(f"server not ready after {timeout} s: {self.output()}")

    def _listening(self) -> bool:
        """Whether the server process itself listens on ``self.port``."""
        try:
            connections = psutil.Process(self.process.pid).net_connections("tcp")
        except psutil.NoSuchProcess:
            return False
        return any(
            c.status == psutil.CONN_LISTEN and c.laddr and c.laddr.port == self.port
            for c in connections
        )

    def output(self) -> str:
        """The tail of the server's log (kept after :meth:`stop`)."""
        if self.log.closed:
            return self._last_output
        self.log.flush()
        return Path(self.log.name).read_text()[-3000:]

    def children(self) -> list[int]:
        """Process ids of the server's children (its run workers among them)."""
        pid = self.process.pid
        out: list[int] = []
        for task in Path(f"/proc/{pid}/task").iterdir():
            text = (task / "children").read_text().split()
            out += [int(x) for x in text]
        return out

    def descendants(self) -> list[int]:
        """Process ids of the server's children, theirs, and so on: the dataset child, the
        run workers' fork server and the workers it forked."""
        out: list[int] = []
        parents = [self.process.pid]
        while parents:
            pid = parents.pop()
            try:
                tasks = list(Path(f"/proc/{pid}/task").iterdir())
                found = [int(x) for t in tasks for x in (t / "children").read_text().split()]
            except OSError:  # gone meanwhile
                continue
            out += found
            parents += found
        return out

    def workers(self) -> list[int]:
        """Process ids of the server's run workers: the descendants that call themselves
        ``mw-idle`` or ``mw-run-<id>`` (app/runs/pool.py; a worker names itself as soon as
        it is forked)."""
        return [pid for pid in self.descendants() if _comm(pid).startswith(WORKER_NAMES)]

    def dataset_child(self) -> int | None:
        """The dataset child's process id (``mw-datasets``), if it runs."""
        return next((p for p in self.descendants() if _comm(p) == DATASET_CHILD), None)

    def wait_versions(self, run_id: int, n: int, timeout: float = 60.0) -> None:
        """Until run ``run_id`` has persisted ``n`` map versions."""
        deadline = time.monotonic() + timeout
        while self.get(f"/api/runs/{run_id}")["n_versions"] < n:
            if time.monotonic() > deadline:
                raise AssertionError(f"run {run_id} has fewer than {n} versions: {self.output()}")
            time.sleep(0.05)

    def kill(self) -> None:
        """``kill -9``: no shutdown handler runs."""
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(timeout=10)
        self.http.close()

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=10)
        self.http.close()
        if not self.log.closed:
            self._last_output = self.output()
            self.log.close()
            Path(self.log.name).unlink(missing_ok=True)

    def get(self, path: str, **kwargs: Any) -> Any:
        response = self.http.get(path, **kwargs)
        return response.json()

    def post(self, path: str, **kwargs: Any) -> httpx.Response:
        return self.http.post(path, **kwargs)

    def wait_run(
        self, run_id: int, until: tuple[str, ...], timeout: float = 120.0
    ) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while True:
            run = self.get(f"/api/runs/{run_id}")
            if run["status"] in until:
                return run
            if time.monotonic() > deadline:
                raise AssertionError(f"run {run_id} still {run['status']}; {self.output()}")
            time.sleep(0.05)


def is_dead(pid: int) -> bool:
    """Gone, or a zombie nobody reaped yet."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return True
    return state in ("Z", "X")


def _comm(pid: int) -> str:
    """What process ``pid`` calls itself (``/proc/<pid>/comm``); empty once it is gone."""
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return ""
