"""The runs list of Runs & compare in Chromium: server-side paging with a page-size selector,
filters (name, estimator, status, dataset), a sweep's runs grouped under one expandable row,
and the per-run actions: rename in place, clone, delete after a confirmation that says how
many map versions go with the run."""

from __future__ import annotations

import re
import time
import uuid

import httpx
from playwright.sync_api import Page, expect

from tests.frontend.browser import shot, wait_run
from tests.frontend.conftest import Console
from tests.support.helpers import log_csv
from tests.support.server import run_body

PLAIN = 11  # with the sweep, 12 entries: two pages of 10


def _dataset(api: httpx.Client) -> dict:
    name = f"runs-list-{uuid.uuid4().hex[:8]}"
    r = api.post(
        "/api/datasets",
        files={"file": ("log.csv", log_csv(600, seed=5).encode())},
        data={"name": name},
    )
    assert r.status_code == 201, r.text
    return r.json()


def _wait_sweep(api: httpx.Client, sweep_id: int) -> dict:
    deadline = time.monotonic() + 180
    while True:
        doc = api.get(f"/api/sweeps/{sweep_id}").json()
        if all(r["status"] not in ("queued", "running") for r in doc["runs"]):
            return doc
        assert time.monotonic() < deadline, doc["counts"]
        time.sleep(0.25)


def test_runs_list_filters_pages_groups_and_manages_runs(
    page: Page, api: httpx.Client, console: Console
) -> None:
    dataset = _dataset(api)
    runs = []
    for i in range(PLAIN):
        estimator = "rls" if i == 3 else "skf"
        name = f"Idle fit {i}" if i % 2 == 0 else f"Load fit {i}"
        body = run_body(dataset["id"], estimator, version_every={"samples": 200}) | {"name": name}
        r = api.post("/api/runs", json=body)
        assert r.status_code == 201, r.text
        runs.append(r.json())
    sweep = api.post(
        "/api/sweeps",
        json={
            "dataset_id": dataset["id"],
            "estimator": "skf",
            "signals": {"y": "y"},
            "table": run_body(0)["table"],
            "config": {"p0": 10.0, "sigma_v": 0.05},
            "parameters": {"sigma_w": [0.001, 0.01, 0.1]},
            "metric": "output_rmse",
            "name": "Noise sweep",
        },
    )
    assert sweep.status_code == 201, sweep.text
    sweep_id = sweep.json()["id"]
    runs = [wait_run(api, r["id"]) for r in runs]
    children = sorted(r["id"] for r in _wait_sweep(api, sweep_id)["runs"])

    page.goto("/compare")
    page.select_option("#runs-dataset", str(dataset["id"]))
    table = page.locator("[data-runs-table]")
    run_rows = table.locator("tbody tr[data-run-id]")
    range_text = page.locator("[data-page-range]")

    # Paging: 12 entries (11 runs, 1 sweep), 25 a page by default, then 10 a page.
    expect(range_text).to_have_text("Showing 1–12 of 12")
    page.select_option("#runs-page-size", "10")
    expect(range_text).to_have_text("Showing 1–10 of 12")
    expect(page.locator("[data-page-prev]")).to_be_disabled()
    expect(run_rows.first).to_have_attribute("data-run-id", str(runs[-1]["id"]))
    # The key metric carries its unit: the output's ppm.
    expect(run_rows.first.locator("td.num").first).to_have_text(re.compile(r"RMSE [\d.,]+ ppm$"))
    # The sweep sits where its first run was created: before the plain runs (newest first).
    group = table.locator(f'tr[data-group-id="{sweep_id}"]')
    expect(group).to_contain_text("Noise sweep")
    expect(group).to_contain_text("3 runs")
    expect(table.locator(f'tr[data-parent-group="{sweep_id}"]')).to_have_count(0)
    toggle = group.locator("[data-group-toggle]")
    expect(toggle).to_have_attribute("aria-expanded", "false")
    toggle.click()
    child_rows = table.locator(f'tr[data-parent-group="{sweep_id}"]')
    expect(child_rows).to_have_count(3)
    assert (
        sorted(int(x) for x in child_rows.evaluate_all("rs => rs.map(r => r.dataset.runId)"))
        == children
    )
    expect(group.locator("[data-group-toggle]")).to_have_attribute("aria-expanded", "true")
    shot(page, "runs-list-grouped")
    group.locator("[data-group-toggle]").click()
    expect(child_rows).to_have_count(0)
    page.click("[data-page-next]")
    expect(range_text).to_have_text("Showing 11–12 of 12")
    expect(page.locator("[data-page-next]")).to_be_disabled()
    page.click("[data-page-prev]")
    expect(range_text).to_have_text("Showing 1–10 of 12")

    # Filters narrow the list on the server and start again at the first page.
    page.fill("#runs-q", "idle")
    expect(range_text).to_have_text("Showing 1–6 of 6")
    expect(run_rows).to_have_count(6)
    page.fill("#runs-q", "")
    page.select_option("#runs-estimator", "rls")
    expect(run_rows).to_have_count(1)
    expect(run_rows.first).to_have_attribute("data-run-id", str(runs[3]["id"]))
    page.select_option("#runs-estimator", "")
    page.select_option("#runs-status", "failed")
    expect(page.locator("[data-runs-empty]")).to_have_text("No run matches these filters.")
    page.select_option("#runs-status", "")
    page.fill("#runs-q", "sweep #2")  # a sweep shows when any of its runs matches
    expect(table.locator("tbody tr")).to_have_count(1)
    table.locator("[data-group-toggle]").click()
    expect(table.locator(f'tr[data-parent-group="{sweep_id}"]')).to_have_count(1)
    page.fill("#runs-q", "")
    expect(range_text).to_have_text("Showing 1–10 of 12")

    # Rename in place: Enter saves; an empty name is refused next to the input.
    target = runs[-1]
    row = table.locator(f'tr[data-run-id="{target["id"]}"]')
    row.locator("[data-rename]").click()
    editor = row.locator("[data-rename-input]")
    expect(editor).to_be_focused()
    console.allow(r"status of 422")
    editor.fill("   ")
    editor.press("Enter")
    expect(row.locator("[data-rename-error]")).to_contain_text("empty")
    editor.fill("Warm idle, final")
    editor.press("Enter")
    expect(row.locator("[data-run-name]")).to_have_text("Warm idle, final")
    assert api.get(f"/api/runs/{target['id']}").json()["name"] == "Warm idle, final"

    # Clone: a new queued run, first in the list.
    row.locator("[data-clone]").click()
    expect(range_text).to_have_text("Showing 1–10 of 13")
    copy_row = run_rows.first
    expect(copy_row.locator("[data-run-name]")).to_have_text("Warm idle, final (copy)")
    copy_id = int(copy_row.get_attribute("data-run-id"))
    copy = api.get(f"/api/runs/{copy_id}").json()
    assert (copy["dataset_id"], copy["estimator"], copy["config"]) == (
        target["dataset_id"],
        target["estimator"],
        target["config"],
    )
    wait_run(api, copy_id)

    # Delete: the dialog says how many versions go with the run.
    victim = runs[0]
    n_versions = api.get(f"/api/runs/{victim['id']}").json()["n_versions"]
    assert n_versions > 1
    page.click("[data-page-next]")
    victim_row = table.locator(f'tr[data-run-id="{victim["id"]}"]')
    victim_row.locator("[data-delete]").click()
    dialog = page.locator("dialog[data-confirm]")
    expect(dialog).to_contain_text(f"with its {n_versions} map versions")
    dialog.locator("[data-confirm-ok]").click()
    expect(victim_row).to_have_count(0)
    expect(range_text).to_have_text(re.compile(r"of 12$"))
    assert api.get(f"/api/runs/{victim['id']}").status_code == 404

    # Compare still works from the list.
    page.click("[data-page-prev]")
    page.check(f"#pick-{runs[4]['id']}")
    page.check(f"#pick-{runs[6]['id']}")
    page.click("[data-compare-selected]")
    expect(page).to_have_url(re.compile(rf"/compare\?runs={runs[4]['id']},{runs[6]['id']}$"))
