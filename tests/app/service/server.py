"""A real ``mapwise serve`` (uvicorn) in a subprocess, for the WebSocket and kill tests."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[3]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """``python -m app.cli serve`` on a free port; ``kill()`` is ``kill -9``."""

    def __init__(
        self,
        database_url: str,
        *,
        demo: bool = False,
        workers: int = 2,
        log_level: str = "warning",
        env: dict[str, str] | None = None,
    ) -> None:
        self.database_url = database_url
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.ws_base = f"ws://127.0.0.1:{self.port}"
        args = [
            sys.executable, "-m", "app.cli", "serve",
            "--host", "127.0.0.1", "--port", str(self.port),
            "--database-url", database_url, "--workers", str(workers), "--log-level", log_level,
        ]  # fmt: skip
        if not demo:
            args.append("--no-demo")
        env = os.environ | {"MAPWISE_CANCEL_POLL_S": "0.05"} | (env or {})
        self.log = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed in stop()
            "w+", prefix="mapwise-serve-", suffix=".log", delete=False
        )
        self.process = subprocess.Popen(
            args, cwd=ROOT, env=env, stdout=self.log, stderr=subprocess.STDOUT,
            start_new_session=True,
        )  # fmt: skip
        self.http = httpx.Client(base_url=self.base, timeout=30)
        self._wait_ready()

    def _wait_ready(self, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited with {self.process.returncode}: {self.output()}")
            try:
                if self.http.get("/api/health").status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.1)
        raise RuntimeError(f"server not ready after {timeout} s: {self.output()}")

    def output(self) -> str:
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

    def workers(self) -> list[int]:
        """Process ids of the server's run workers (its spawned pool processes)."""
        out = []
        for pid in self.children():
            try:
                if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    out.append(pid)
            except OSError:  # gone meanwhile
                pass
        return out

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
        self.log.close()

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
