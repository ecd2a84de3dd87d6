"""``scripts/start.sh``, the README's first command, on an environment that is already
installed (as ``scripts/test.sh`` leaves it): it says so and skips the install, starts the
dashboard on a new database with the demo run and prints its URL; a second start skips the
install again and finds the demo in place (one run, not two). How long the second start
takes is measured, not asserted here (README: about 2 s)."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from tests.support.server import free_port

REPO = Path(__file__).resolve().parents[3]
pytestmark = pytest.mark.slow


def _start(tmp_path: Path, port: int, log: Path) -> subprocess.Popen[bytes]:
    env = {k: v for k, v in os.environ.items() if k != "MAPWISE_REQUIRE_AUTH"}
    env["MAPWISE_STORE_URL"] = str(tmp_path / "store")
    with log.open("wb") as out:
        return subprocess.Popen(
            [
                "bash", str(REPO / "scripts" / "start.sh"),
                "--port", str(port), "--database-url", f"sqlite:///{tmp_path / 'mapwise.db'}",
            ],
            cwd=REPO, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip


def _serve_until_healthy(tmp_path: Path, name: str) -> str:
    """Start, wait for /api/health, read the run count, stop; returns the script's output."""
    port = free_port()
    log = tmp_path / f"{name}.log"
    process = _start(tmp_path, port, log)
    try:
        deadline = time.monotonic() + 120
        while True:
            assert process.poll() is None, log.read_text()
            try:
                if httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.1)
        runs = httpx.get(f"http://127.0.0.1:{port}/api/runs", timeout=10).json()
        assert runs["total"] == 1, runs
        assert runs["items"][0]["status"] == "succeeded", runs["items"][0]
    finally:
        os.killpg(process.pid, signal.SIGTERM)
        process.wait(timeout=30)
    return log.read_text()


def test_start_skips_a_current_install_and_keeps_the_demo(tmp_path: Path) -> None:
    stamps = list((REPO / ".venv").glob(".mapwise-install-*")) + list(
        (REPO / ".venv").glob(".mapwise-serve-*")
    )
    assert stamps, "run scripts/test.sh first: it installs ./.venv and stamps it"
    first = _serve_until_healthy(tmp_path, "first")
    assert "./.venv is current; starting" in first, first
    assert "[1/3]" not in first, first
    assert "new database" in first, first
    assert "demo run 1" in first, first
    assert "/runs/1" in first, first
    second = _serve_until_healthy(tmp_path, "second")
    assert "./.venv is current; starting" in second, second
    assert "[1/3]" not in second, second
    assert "new database" not in second, second
    assert "/runs/1" in second, second
