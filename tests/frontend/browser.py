"""What the browser tests and ``scripts/screenshot.py`` share: Debian's Chromium with the
flags it needs in a container, and a real ``mapwise serve`` (:class:`tests.support.server.Server`)
on a temporary SQLite database."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import httpx

from tests.support.server import Server

if TYPE_CHECKING:
    from playwright.sync_api import Page

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking"]
VIEWPORT = {"width": 1400, "height": 900}
ROOT = Path(__file__).resolve().parents[2]
EXAMPLE_CSV = ROOT / "app" / "data" / "example_nox.csv"
ARTIFACTS = ROOT / "tests" / "artifacts"
# ``page.evaluate(DROP_FILE, [text, name])``: drop a CSV file on the Datasets view's zone.
DROP_FILE = """
([text, name]) => {
  const zone = document.querySelector(".dropzone");
  const dt = new DataTransfer();
  dt.items.add(new File([text], name, { type: "text/csv" }));
  for (const type of ["dragenter", "dragover", "drop"]) {
    zone.dispatchEvent(new DragEvent(type, { dataTransfer: dt, bubbles: true, cancelable: true }));
  }
}
"""


def start_server(workdir: Path) -> Server:
    """``mapwise serve`` on a free port and a new SQLite file in ``workdir`` (no demo data);
    returns once ``/api/health`` answers."""
    return Server(f"sqlite:///{workdir / 'db.sqlite'}")


def upload_example(api: httpx.Client, name: str) -> dict:
    """The bundled NOx log (50 Hz, 150 s) as a dataset, through the real upload endpoint."""
    with EXAMPLE_CSV.open("rb") as f:
        r = api.post(
            "/api/datasets", files={"file": (EXAMPLE_CSV.name, f, "text/csv")}, data={"name": name}
        )
    if r.status_code != 201:
        raise RuntimeError(f"upload failed: {r.status_code} {r.text}")
    return r.json()


def shot(page: Page, name: str) -> Path:
    """Save a full-page screenshot as a test artifact."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


def wait_run(api: httpx.Client, run_id: int, timeout_s: float = 120.0) -> dict:
    """Poll the run until it leaves queued/running."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        run = api.get(f"/api/runs/{run_id}").json()
        if run["status"] not in ("queued", "running"):
            return run
        time.sleep(0.25)
    raise AssertionError(f"run {run_id} still {run['status']} after {timeout_s} s")


def scenario_run(
    api: httpx.Client,
    *,
    scenario: str,
    estimator: str,
    seed: int,
    duration_s: float,
    config: dict | None = None,
) -> tuple[dict, dict]:
    """A finished run of ``estimator`` on the first ``duration_s`` of a simulated ``scenario``,
    with the scenario's own setup (grid, signals, settings; ``config`` overrides settings),
    so its known-truth metrics are scored; returns ``(run, setup)``."""
    sim = api.post(
        "/api/datasets/simulate",
        json={"scenario": scenario, "seed": seed, "duration_s": duration_s},
        timeout=120,
    )
    assert sim.status_code == 201, sim.text
    dataset = sim.json()
    setup = api.get(f"/api/datasets/{dataset['id']}/setup").json()["estimators"][estimator]
    body = {
        "dataset_id": dataset["id"],
        "estimator": estimator,
        "signals": setup["signals"],
        "config": {**setup["config"], **(config or {})},
    }
    if setup["table"] is not None:
        body["table"] = setup["table"]
    created = api.post("/api/runs", json=body)
    assert created.status_code == 201, created.text
    run = wait_run(api, created.json()["id"])
    assert run["status"] == "succeeded", run["error"]
    return run, setup


def plot_data(page: Page, selector: str) -> list[dict]:
    """The traces Plotly currently draws in the element matched by ``selector``."""
    return page.eval_on_selector(
        selector,
        "el => (el.data || []).map(t => ({type: t.type || 'scatter', name: t.name ?? null, "
        "z: t.z ?? null, x: Array.from(t.x ?? []), y: Array.from(t.y ?? []), "
        "zmin: t.zmin ?? null, zmax: t.zmax ?? null}))",
    )


# The dashboard's own view routes (the History-API router handles them in the page).


def serves_group_views(server: Server) -> bool:
    """Whether ``mapwise serve`` answers ``/sweeps`` and ``/batches`` with the dashboard page."""
    with server.api() as client:
        return all(
            client.get(path).headers.get("content-type", "").startswith("text/html")
            for path in ("/sweeps", "/sweeps/1", "/batches", "/batches/1")
        )
