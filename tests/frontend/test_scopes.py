"""Token scopes in the dashboard: against a server that requires tokens, a read-only token sees
the datasets and runs but none of the controls that need ``run`` (New run, upload, simulate,
cancel, resume, label) or ``admin`` (delete, save as base map); an admin token sees them all."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass

import httpx
import pytest
from playwright.sync_api import Locator, Page, expect

from tests.frontend.browser import ROOT, upload_example
from tests.support.server import Server, run_body


@dataclass(frozen=True)
class Secured:
    """The server of this module and what it holds: tokens by name, a dataset, a run that is
    still going and one cancelled after its first map version."""

    server: Server
    tokens: dict[str, str]
    dataset: dict
    running: int
    cancelled: int


def _create_token(url: str, name: str, *scopes: str) -> str:
    args = [sys.executable, "-m", "app.cli", "token", "create", "--name", name]
    args += [a for s in scopes for a in ("--scope", s)] + ["--database-url", url]
    done = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=60, check=True)
    return done.stdout.strip()


@pytest.fixture(scope="module")
def secured(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Secured]:
    url = f"sqlite:///{tmp_path_factory.mktemp('mapwise-scopes') / 'db.sqlite'}"
    server = Server(url, env={"MAPWISE_REQUIRE_AUTH": "1"})
    try:
        tokens = {
            "read": _create_token(url, "read-only", "read"),
            "admin": _create_token(url, "admin", "read", "run", "admin"),
        }
        auth = {"Authorization": f"Bearer {tokens['admin']}"}
        with httpx.Client(base_url=server.url, timeout=60, headers=auth) as api:
            assert httpx.get(f"{server.url}/api/datasets").status_code == 401
            dataset = upload_example(api, "scoped-log")
            # paced to real time (150 s of log): still going while the tests look at it
            running = _start(api, dataset["id"], pace=1)
            # 15 s at the least (pace only slows a run down), a map version every 0.5 s
            cancelled = _start(api, dataset["id"], pace=10)
            _wait_first_version(api, cancelled, 60.0)
            assert api.post(f"/api/runs/{cancelled}/cancel").status_code < 300
            _wait_status(api, cancelled, "cancelled")
        yield Secured(server, tokens, dataset, running, cancelled)
    finally:
        server.stop()


def _start(api: httpx.Client, dataset_id: int, pace: float) -> int:
    """An SKF run of NOx over a 3×3 speed × fuel table, ``pace`` times real time."""
    table = {
        "axes": [
            {"name": "speed_rpm", "breakpoints": [500.0, 2500.0, 4500.0]},
            {"name": "fuel_mg_per_stroke", "breakpoints": [0.0, 35.0, 70.0]},
        ]
    }
    config = {"theta0": 300, "p0": 1e4, "sigma_w": 5, "sigma_v": 50, "pace": pace}
    config["version_every"] = {"seconds": 5}
    body = run_body(dataset_id, signals={"y": "nox_ppm"}, table=table, **config)
    response = api.post("/api/runs", json=body)
    assert response.status_code == 201, response.text
    return int(response.json()["id"])


def _wait_first_version(api: httpx.Client, run_id: int, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while api.get(f"/api/runs/{run_id}").json()["n_versions"] < 1:
        if time.monotonic() > deadline:
            raise AssertionError(f"run {run_id} has no map version after {timeout_s} s")
        time.sleep(0.1)


def _wait_status(api: httpx.Client, run_id: int, status: str, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while (now := api.get(f"/api/runs/{run_id}").json()["status"]) != status:
        if time.monotonic() > deadline:
            raise AssertionError(f"run {run_id} is {now}, not {status}")
        time.sleep(0.05)


@pytest.fixture(scope="module")
def server(secured: Secured) -> Server:
    """The conftest's ``page`` opens this module's server (tokens required)."""
    return secured.server


def _open(page: Page, secured: Secured, who: str, path: str) -> None:
    """Store ``who``'s token the way the token prompt does, then open ``path`` once the page
    knows the caller's scopes."""
    token = json.dumps(secured.tokens[who])
    page.add_init_script(f"localStorage.setItem('mapwise.token', {token})")
    page.goto(path)
    expected = "read" if who == "read" else "read run admin"
    expect(page.locator("html")).to_have_attribute("data-scopes", expected)


def _datasets_controls(page: Page, name: str) -> dict[str, Locator]:
    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    return {
        "nav New run": page.locator("a[data-section=new-run]"),
        # CSS, not roles: a hidden element is not in the accessibility tree, and these must be
        # on the page (hidden), not missing, for the read-only test to mean anything
        "upload card": page.locator(".card-head h2", has_text="Upload a log"),
        "simulate card": page.locator(".card-head h2", has_text="Simulate a scenario"),
        "row New run": row.locator(f'a[aria-label="New run on {name}"]'),
        "row delete": row.locator(f'button[aria-label="Delete dataset {name}"]'),
    }


def test_read_only_token_sees_the_datasets_but_no_upload_simulate_or_delete(
    page: Page, secured: Secured
) -> None:
    _open(page, secured, "read", "/datasets")
    name = secured.dataset["name"]
    expect(page.locator("[data-dataset-list] tbody tr", has_text=name)).to_be_visible()
    expect(page.locator("a[data-section=datasets]")).to_be_visible()
    for label, control in _datasets_controls(page, name).items():
        expect(control, f"{label} is offered to a read-only token").to_be_hidden()
        assert control.count() == 1, f"{label} is missing from the page, not just hidden"
    # no token prompt: the token is valid, only narrow
    expect(page.locator("dialog[open]")).to_have_count(0)


def test_admin_token_sees_upload_simulate_and_delete(page: Page, secured: Secured) -> None:
    _open(page, secured, "admin", "/datasets")
    for label, control in _datasets_controls(page, secured.dataset["name"]).items():
        expect(control, f"{label} is not offered to an admin token").to_be_visible()


def _run_controls(page: Page) -> dict[str, Locator]:
    return {
        "Cancel": page.locator("[data-cancel]"),
        "Resume": page.locator("[data-resume]"),
        "Save label": page.locator("[data-save-label]"),
        "Save as base map": page.locator("[data-base-map]"),
    }


def test_read_only_token_sees_runs_without_cancel_resume_label_or_base_map(
    page: Page, secured: Secured
) -> None:
    _open(page, secured, "read", f"/runs/{secured.running}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("running")
    expect(_run_controls(page)["Cancel"]).to_be_hidden()

    page.goto(f"/runs/{secured.cancelled}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("cancelled")
    expect(page.locator("[data-plot=map]")).to_be_visible()
    for label, control in _run_controls(page).items():
        expect(control, f"{label} is offered to a read-only token").to_be_hidden()
        assert control.count() == 1, f"{label} is missing from the page, not just hidden"


def test_admin_token_sees_cancel_resume_label_and_base_map(page: Page, secured: Secured) -> None:
    _open(page, secured, "admin", f"/runs/{secured.running}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("running")
    expect(_run_controls(page)["Cancel"]).to_be_visible()

    page.goto(f"/runs/{secured.cancelled}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("cancelled")
    controls = _run_controls(page)
    expect(controls["Cancel"]).to_be_hidden()  # the run is over: the status rules, not scopes
    for label in ("Resume", "Save label", "Save as base map"):
        expect(controls[label], f"{label} is not offered to an admin token").to_be_visible()


def test_read_only_token_opening_new_run_directly_gets_no_start_button(
    page: Page, secured: Secured
) -> None:
    """The nav link is hidden, but a typed URL still shows the form (read-only callers may
    look at it); its Start button, which could only earn a 403, is not offered."""
    _open(page, secured, "read", f"/runs/new?dataset={secured.dataset['id']}")
    expect(page.locator("[data-run-form]")).to_be_visible()
    expect(page.locator("a[data-section=new-run]")).to_be_hidden()
    expect(page.locator("[data-start]")).to_be_hidden()
    assert page.locator("[data-start]").count() == 1


def test_admin_token_gets_the_start_button(page: Page, secured: Secured) -> None:
    _open(page, secured, "admin", f"/runs/new?dataset={secured.dataset['id']}")
    expect(page.locator("a[data-section=new-run]")).to_be_visible()
    expect(page.locator("[data-start]")).to_be_visible()
