"""Sweeps and fleet batches in the dashboard: a grid sweep started from the New-run form,
refreshed live while it runs, ranked by its metric as the API ranks it, its parameter-vs-metric
plot and grid heatmap, a click on the best row or point opening that run; a bad parameter value
refused next to its field; a batch over three vehicles' logs started from the Datasets view,
its aggregate map and each vehicle's deviation map (|z| > 3 outlined) against the API's
aggregate; the list pages, labels and reloads."""

from __future__ import annotations

import csv
import io
import re
import uuid

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import (
    EXAMPLE_CSV,
    Server,
    plot_data,
    serves_group_views,
    shot,
    upload_example,
)
from tests.frontend.conftest import Console
from tests.frontend.test_compare_versions_view import GRID
from tests.frontend.test_run_view import RUN_URL, heatmap_z, run_form_url
from tests.frontend.test_views import UNLABELLED

SWEEP_URL = re.compile(r"/sweeps/(\d+)$")
BATCH_URL = re.compile(r"/batches/(\d+)(\?vehicle=\d+)?$")
FIXED = {"theta0": 300, "p0": 1e4, "sigma_w": 5, "sigma_v": 50}

# Counts Plotly.react and Plotly.newPlot calls per plot (data-plot) from the moment Plotly.js
# defines window.Plotly: a live refresh must update the plots in place.
COUNT_DRAWS = """
(() => {
  const rec = { react: {}, newPlot: 0 };
  window.__draws = rec;
  let plotly;
  Object.defineProperty(window, "Plotly", {
    configurable: true,
    get() { return plotly; },
    set(P) {
      const react = P.react;
      const newPlot = P.newPlot;
      P.react = function (gd, ...rest) {
        const key = gd?.dataset?.plot ?? "?";
        rec.react[key] = (rec.react[key] ?? 0) + 1;
        return react.call(this, gd, ...rest);
      };
      P.newPlot = function (...args) { rec.newPlot += 1; return newPlot.apply(this, args); };
      plotly = P;
    },
  });
})();
"""


def deviating_csv() -> str:
    """The example log of a vehicle whose NOx reads high above 2000 rpm (a drifting sensor)."""
    rows = list(csv.reader(EXAMPLE_CSV.read_text().splitlines()))
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(rows[0])
    for time_s, speed, fuel, nox in rows[1:]:
        value = float(nox) * 1.6 + 80 if float(speed) > 2000 else float(nox)
        writer.writerow([time_s, speed, fuel, f"{value:.1f}"])
    return out.getvalue()


@pytest.fixture(scope="module")
def fleet(server: Server) -> list[dict]:
    """Three vehicles' logs: two alike, the third deviating in part of the map."""
    tag = uuid.uuid4().hex[:6]
    with server.api() as api:
        found = [upload_example(api, f"fleet-{tag}-a"), upload_example(api, f"fleet-{tag}-b")]
        r = api.post(
            "/api/datasets",
            files={"file": ("deviating.csv", deviating_csv(), "text/csv")},
            data={"name": f"fleet-{tag}-drift"},
        )
        assert r.status_code == 201, r.text
        found.append(r.json())
    return found


def transpose(m: list[list]) -> list[list]:
    """values[i][j] (i along the first axis) → the heatmap's z[j][i]."""
    return [list(col) for col in zip(*m, strict=True)]


def row_ids(page: Page, table: str) -> list[int]:
    return [
        int(x)
        for x in page.locator(f"{table} tbody tr").evaluate_all(
            "rows => rows.map(r => r.dataset.runId)"
        )
    ]


def click_point(page: Page, plot: str, x: float, y: float) -> None:
    """Click where Plotly draws the data point (x, y) of the plot."""
    px, py = page.eval_on_selector(
        plot,
        """(el, [x, y]) => {
          const xa = el._fullLayout.xaxis, ya = el._fullLayout.yaxis;
          const box = el.querySelector('.nsewdrag').getBoundingClientRect();
          return [box.left + xa.l2p(xa.d2l(x)), box.top + ya.l2p(ya.d2l(y))];
        }""",
        [x, y],
    )
    page.mouse.move(px - 30, py - 30)
    page.mouse.move(px, py, steps=5)
    page.mouse.click(px, py)


def sweep_form(page: Page, dataset_id: int) -> None:
    """The New-run form, switched to a sweep, with the fixed settings filled in."""
    page.goto(run_form_url(dataset_id))
    page.locator('[data-mode="sweep"]').click()
    expect(page.locator("[data-page-title]")).to_have_text("New sweep")
    expect(page.locator('[data-mode="sweep"]')).to_have_attribute("aria-pressed", "true")
    expect(page).to_have_url(re.compile(r"[?&]mode=sweep(&|$)"))
    page.fill("#cfg-skf-theta0", "300")
    page.fill("#cfg-skf-p0", "10000")


def sweep_parameters(page: Page, first: str, second: str) -> None:
    page.select_option("#sweep-param-0", "sigma_w")
    page.fill("#sweep-values-0", first)
    page.locator("[data-add-sweep-param]").click()
    page.select_option("#sweep-param-1", "sigma_v")
    page.fill("#sweep-values-1", second)


def test_the_server_serves_the_sweep_and_batch_urls(server: Server) -> None:
    """A reload or a pasted link of the new views gets the dashboard from the server itself."""
    assert serves_group_views(server)


def test_a_grid_sweep_from_the_form_is_ranked_plotted_and_opens_its_runs(
    page: Page, api: httpx.Client, server: Server, fleet: list[dict]
) -> None:
    page.add_init_script(COUNT_DRAWS)
    sweep_form(page, fleet[0]["id"])
    sweep_parameters(page, "0.5, 5, 50", "10, 50")
    expect(page.locator("[data-sweep-count]")).to_contain_text("6 runs: the grid of 3 × 2 values")
    start = page.locator("[data-start]")
    expect(start).to_have_text("Start sweep (6 runs)")
    # 150 s of log in 1.5 s a run: the view refreshes while they run.
    page.select_option("#run-pace", "100")
    page.fill("#run-name", "sigma sweep")
    with page.expect_request(lambda r: r.url.endswith("/api/sweeps") and r.method == "POST") as req:
        start.click()
    body = req.value.post_data_json
    assert body["parameters"] == {"sigma_w": [0.5, 5, 50], "sigma_v": [10, 50]}
    assert "sigma_w" not in body["config"]
    assert "sigma_v" not in body["config"]
    assert body["config"]["pace"] == 100
    assert body["metric"] == "output_rmse"
    assert body["order"] == "min"
    assert body["name"] == "sigma sweep"
    expect(page).to_have_url(SWEEP_URL)
    sweep_id = int(SWEEP_URL.search(page.url).group(1))

    # Live: the runs are still going when the view first shows them, and finish in place.
    table = page.locator("[data-sweep-table]")
    expect(table.locator("tbody tr")).to_have_count(6)
    statuses = table.locator("tbody .badge").all_inner_texts()
    assert any(s in ("queued", "running") for s in statuses), statuses
    scatter = '[data-plot="sweep-scatter"]'
    page.locator(f"{scatter} .main-svg").first.wait_for(state="attached")
    page.eval_on_selector(scatter, "el => { el.__first = true; }")
    shot(page, "sweep-running")
    expect(table.locator('tbody .badge[data-status="succeeded"]')).to_have_count(6, timeout=60_000)
    expect(page.locator("[data-group-progress] .pct")).to_have_text("6 of 6 runs finished")
    page.wait_for_function(f"() => document.querySelector('{scatter}').data?.[0]?.x?.length === 6")
    draws = page.evaluate("() => window.__draws")
    assert draws["newPlot"] == 0, draws
    assert draws["react"].get("sweep-scatter", 0) >= 2, draws
    assert page.eval_on_selector(scatter, "el => el.__first === true")  # the same plot, updated

    # The table ranks as the API does: best first by the metric.
    sweep = api.get(f"/api/sweeps/{sweep_id}").json()
    runs = sweep["runs"]
    assert [r["status"] for r in runs] == ["succeeded"] * 6
    assert row_ids(page, "[data-sweep-table]") == [r["id"] for r in runs]
    shown = [
        float(v)
        for v in table.locator("tbody td[data-metric]").evaluate_all(
            "tds => tds.map(td => td.dataset.metric)"
        )
    ]
    assert shown == [r["metric"] for r in runs]
    assert shown == sorted(shown)
    best = sweep["best_run_id"]
    assert best == runs[0]["id"]
    expect(table.locator(f'tr[data-run-id="{best}"]')).to_have_class(re.compile(r"best-row"))
    by_id = {r["id"]: r for r in runs}
    cells = table.locator(f'tr[data-run-id="{runs[1]["id"]}"] td')
    expect(cells.nth(2)).to_have_text(f"{runs[1]['params']['sigma_w']:g}")
    expect(cells.nth(3)).to_have_text(f"{runs[1]['params']['sigma_v']:g}")
    top = ",".join(str(r["id"]) for r in runs[:3])
    expect(page.locator("[data-compare-top]")).to_have_attribute("href", f"/compare?runs={top}")

    # Sorting by a column, kept in the URL and over a reload.
    header = page.locator('th:has([data-sort="metric"])')
    page.locator('[data-sort="metric"]').click()
    expect(header).to_have_attribute("aria-sort", "ascending")
    page.locator('[data-sort="metric"]').click()
    expect(header).to_have_attribute("aria-sort", "descending")
    expect(page.locator('[data-sort="metric"]')).to_be_focused()
    assert row_ids(page, "[data-sweep-table]") == [r["id"] for r in reversed(runs)]
    page.locator('[data-sort="sigma_w"]').click()
    order = row_ids(page, "[data-sweep-table]")
    assert [by_id[i]["params"]["sigma_w"] for i in order] == sorted(
        r["params"]["sigma_w"] for r in runs
    )
    page.locator('[data-sort="metric"]').click()
    page.locator('[data-sort="metric"]').click()
    expect(page).to_have_url(re.compile(rf"/sweeps/{sweep_id}\?sort=metric:desc$"))

    # One point per run, the metric against σw on a log axis (0.5 … 50 spans two decades).
    traces = plot_data(page, scatter)
    assert len(traces) == 1
    points = sorted(zip(traces[0]["x"], traces[0]["y"], strict=True))
    assert points == sorted((r["params"]["sigma_w"], r["metric"]) for r in runs)
    assert page.eval_on_selector(scatter, "el => el._fullLayout.xaxis.type") == "log"
    # The grid heatmap: the metric of each (σw, σv) cell.
    z = heatmap_z(page, '[data-plot="sweep-heatmap"]')
    assert sorted(v for row in z for v in row) == sorted(r["metric"] for r in runs)
    shot(page, "sweep-done")

    # The other parameter on the x axis: linear (10 … 50), in the URL, kept over a reload.
    page.select_option("#sweep-x", "sigma_v")
    page.wait_for_function(
        f"() => document.querySelector('{scatter}')._fullLayout.xaxis.type === 'linear'"
    )
    expect(page).to_have_url(re.compile(r"\?x=sigma_v&sort=metric:desc$"))
    page.reload()
    expect(page.locator("#sweep-x")).to_have_value("sigma_v")
    expect(header).to_have_attribute("aria-sort", "descending")
    assert row_ids(page, "[data-sweep-table]") == [r["id"] for r in reversed(runs)]
    page.wait_for_function(
        f"() => document.querySelector('{scatter}')?._fullLayout?.xaxis?.type === 'linear'"
    )
    points = sorted(zip(*(plot_data(page, scatter)[0][k] for k in ("x", "y")), strict=True))
    assert points == sorted((r["params"]["sigma_v"], r["metric"]) for r in runs)

    # A click on the best run's point opens it; so does a click on its row.
    click_point(page, scatter, by_id[best]["params"]["sigma_v"], by_id[best]["metric"])
    expect(page).to_have_url(re.compile(rf"/runs/{best}$"))
    page.go_back()
    expect(page).to_have_url(re.compile(rf"/sweeps/{sweep_id}\?"))
    page.locator(f'[data-sweep-table] tr[data-run-id="{best}"] td').nth(4).click()
    expect(page).to_have_url(RUN_URL)
    assert int(RUN_URL.search(page.url).group(1)) == best


def test_a_bad_parameter_value_is_refused_next_to_its_field(
    page: Page, api: httpx.Client, server: Server, console: Console, fleet: list[dict]
) -> None:
    console.allow(r"status of 422")
    before = api.get("/api/sweeps").json()["total"]
    sweep_form(page, fleet[0]["id"])
    sweep_parameters(page, "1, 5", "10, -1")
    page.locator("[data-start]").click()
    values = page.locator("#sweep-values-1")
    expect(values).to_have_attribute("aria-invalid", "true")
    error = page.locator('[data-sweep-row="1"] .field-error')
    expect(error).to_contain_text("sigma_v")
    expect(error).to_contain_text("greater than 0")
    # Next to the σv values, inside their field; the σw values are fine.
    expect(values.locator("xpath=ancestor::div[contains(@class, 'field')][1]")).to_contain_text(
        "greater than 0"
    )
    expect(page.locator("#sweep-values-0")).not_to_have_attribute("aria-invalid", "true")
    expect(values).to_be_focused()
    assert api.get("/api/sweeps").json()["total"] == before  # nothing was stored
    expect(page).to_have_url(re.compile(r"/runs/new\?"))

    # A range needs a sample size (the client says so before asking the API).
    page.fill("#sweep-values-1", "10, 50")
    page.select_option("#sweep-kind-0", "range")
    page.fill("#sweep-min-0", "0.5")
    page.fill("#sweep-max-0", "50")
    page.select_option("#sweep-scale-0", "log")
    expect(page.locator("[data-sweep-count]")).to_contain_text("give the number of samples")
    page.fill("#sweep-samples", "4")
    expect(page.locator("[data-start]")).to_have_text("Start sweep (4 runs)")
    with page.expect_request(lambda r: r.url.endswith("/api/sweeps") and r.method == "POST") as req:
        page.locator("[data-start]").click()
    body = req.value.post_data_json
    assert body["parameters"]["sigma_w"] == {
        "min": 0.5,
        "max": 50,
        "scale": "log",
        "integer": False,
    }
    assert body["samples"] == 4
    assert body["seed"] == 0
    expect(page).to_have_url(SWEEP_URL)
    sweep = api.get(f"/api/sweeps/{SWEEP_URL.search(page.url).group(1)}").json()
    assert sweep["request"]["samples"] == 4
    expect(page.locator("[data-sweep-table] tbody tr")).to_have_count(4)
    expect(page.locator('[data-plot="sweep-heatmap"]')).to_have_count(0)  # random draws: no grid


def test_a_batch_over_three_vehicles_shows_the_aggregate_and_each_deviation(
    page: Page, api: httpx.Client, server: Server, fleet: list[dict]
) -> None:
    ids = [d["id"] for d in fleet]
    page.goto("/datasets")
    run_batch = page.locator("[data-run-batch]")
    expect(run_batch).to_be_disabled()
    for dataset_id in ids:
        page.check(f"#pick-ds-{dataset_id}")
    expect(run_batch).to_have_text("Run batch on 3 datasets…")
    run_batch.click()
    expect(page.locator("[data-page-title]")).to_have_text("New batch")
    expect(page).to_have_url(re.compile(rf"mode=batch&datasets={','.join(map(str, ids))}$"))
    for dataset_id in ids:
        expect(page.locator(f"#batch-ds-{dataset_id}")).to_be_checked()
    expect(page.locator("#est-skf")).to_have_attribute("type", "radio")
    for key, value in FIXED.items():
        page.fill(f"#cfg-skf-{key}", str(value))
    page.select_option("#sig-y", "nox_ppm")
    page.fill("#axis-0-bp", ", ".join(map(str, GRID["axes"][0]["breakpoints"])))
    page.locator("#axis-0-bp").dispatch_event("change")
    page.fill("#axis-1-bp", ", ".join(map(str, GRID["axes"][1]["breakpoints"])))
    page.locator("#axis-1-bp").dispatch_event("change")
    start = page.locator("[data-start]")
    expect(start).to_have_text("Start batch (3 datasets)")
    with page.expect_request(lambda r: r.url.endswith("/api/batches") and r.method == "POST") as r:
        start.click()
    assert r.value.post_data_json["dataset_ids"] == sorted(ids)
    expect(page).to_have_url(BATCH_URL)
    batch_id = int(BATCH_URL.search(page.url).group(1))

    # Once every run has succeeded: the aggregate map is the API's merge, cell by cell.
    page.locator('[data-plot="aggregate"] .main-svg').first.wait_for(
        state="attached", timeout=60_000
    )
    batch = api.get(f"/api/batches/{batch_id}").json()
    agg = batch["aggregate"]
    assert agg is not None
    assert len(agg["run_ids"]) == 3
    succeeded = page.locator('[data-batch-table] tbody .badge[data-status="succeeded"]')
    expect(succeeded).to_have_count(3)
    assert row_ids(page, "[data-batch-table]") == [r["id"] for r in batch["runs"]]
    assert heatmap_z(page, '[data-plot="aggregate"]') == transpose(agg["values"])
    title = "el => [el._fullLayout.xaxis.title.text, el._fullLayout.yaxis.title.text]"
    titles = page.eval_on_selector('[data-plot="aggregate"]', title)
    assert titles == ["speed_rpm [rpm]", "fuel_mg_per_stroke [mg/stroke]"]

    deviating = agg["deviating_cells"]
    assert deviating[2] > 0, deviating  # the drifting vehicle stands out
    # It is the one shown first; its bar is the tallest.
    picker = page.locator("#batch-vehicle")
    vehicles = [r["id"] for r in batch["runs"]]
    worst = vehicles.index(agg["run_ids"][max(range(3), key=lambda k: deviating[k])]) + 1
    expect(picker).to_have_value(str(worst))
    bars = plot_data(page, '[data-plot="deviating-bars"]')
    order = [agg["run_ids"].index(r["id"]) for r in batch["runs"]]
    assert bars[0]["y"] == [deviating[k] for k in order]
    shot(page, "batch-aggregate")

    deviation = '[data-plot="deviation"]'
    for vehicle in (1, 3, 2):
        picker.select_option(str(vehicle))
        expect(page).to_have_url(re.compile(rf"/batches/{batch_id}\?vehicle={vehicle}$"))
        k = agg["run_ids"].index(batch["runs"][vehicle - 1]["id"])
        page.wait_for_function(
            "([sel, z]) => JSON.stringify(document.querySelector(sel).data?.[0]?.z)"
            " === JSON.stringify(z)",
            arg=[deviation, transpose(agg["z"][k])],
        )
        traces = plot_data(page, deviation)
        assert traces[0]["z"] == transpose(agg["z"][k])
        assert (traces[0]["zmin"], traces[0]["zmax"]) == (-5, 5)
        outlined = next(t for t in traces if t["name"] == "outlined cells")
        assert len(outlined["x"]) % 6 == 0
        assert len(outlined["x"]) // 6 == deviating[k]
        expect(page.locator("[data-deviating-count]")).to_contain_text(
            f"{deviating[k]} cell{'' if deviating[k] == 1 else 's'} with |z| > 3"
        )
        expect(page.locator(f'[data-batch-table] tr[data-vehicle="{vehicle}"]')).to_have_attribute(
            "aria-current", "true"
        )
    shot(page, "batch-deviation")

    # The vehicle survives a reload; the table's buttons pick a vehicle too.
    page.reload()
    expect(picker).to_have_value("2")
    page.locator('[data-show-vehicle="3"]').click()
    expect(picker).to_have_value("3")
    expect(page.locator('[data-show-vehicle="3"]')).to_be_focused()
    expect(page).to_have_url(re.compile(r"\?vehicle=3$"))

    # In the runs list the batch's three runs sit under one expandable row, linked to it.
    page.goto("/compare")
    group = page.locator(
        f'[data-runs-table] tr[data-group-id="{batch_id}"][data-group-kind="batch"]'
    )
    expect(group).to_contain_text("Batch")
    expect(group.locator("[data-group-size]")).to_have_text("· 3 runs")
    expect(group.locator(f'a[href="/batches/{batch_id}"]')).to_be_visible()
    group.locator("[data-group-toggle]").click()
    children = page.locator(f'[data-runs-table] tr[data-parent-group="{batch_id}"]')
    expect(children).to_have_count(3)
    shown = sorted(int(x) for x in children.evaluate_all("rs => rs.map(r => r.dataset.runId)"))
    assert shown == sorted(r["id"] for r in batch["runs"])


def test_the_lists_and_views_have_urls_labels_and_navigation(
    page: Page, api: httpx.Client, server: Server, fleet: list[dict]
) -> None:
    r = api.post(
        "/api/sweeps",
        json={
            "dataset_id": fleet[0]["id"],
            "estimator": "skf",
            "signals": {"y": "nox_ppm"},
            "table": GRID,
            "config": {"theta0": 300, "p0": 1e4},
            "parameters": {"sigma_w": [1, 10]},
            "name": f"listed-{uuid.uuid4().hex[:6]}",
        },
    )
    assert r.status_code == 201, r.text
    sweep = r.json()
    r = api.post(
        "/api/batches",
        json={
            "dataset_ids": [d["id"] for d in fleet[:2]],
            "estimator": "skf",
            "signals": {"y": "nox_ppm"},
            "table": GRID,
            "config": FIXED,
        },
    )
    assert r.status_code == 201, r.text
    batch = r.json()
    nav = page.get_by_role("navigation", name="Main")
    for url, title, section in (
        ("/sweeps", "Sweeps", "Sweeps"),
        (f"/sweeps/{sweep['id']}", sweep["name"], "Sweeps"),
        ("/batches", "Batches", "Batches"),
        (f"/batches/{batch['id']}", batch["name"], "Batches"),
    ):
        page.goto(url)
        expect(page.locator("[data-page-title]")).to_have_text(title)
        expect(nav.get_by_role("link", name=section)).to_have_attribute("aria-current", "page")
        page.wait_for_load_state("networkidle")
        assert page.evaluate(UNLABELLED) == [], url
        before = page.url
        page.reload()
        expect(page.locator("[data-page-title]")).to_have_text(title)
        assert page.url == before
    shot(page, "batch-view")

    # From the lists to a group and on, by keyboard.
    page.goto("/sweeps")
    link = page.locator(f'[data-sweep-list] a[href="/sweeps/{sweep["id"]}"]')
    link.focus()
    page.keyboard.press("Enter")
    expect(page).to_have_url(re.compile(rf"/sweeps/{sweep['id']}$"))
    expect(page.locator("[data-page-title]")).to_be_focused()
    expect(page.locator("[data-sweep-table] tbody tr")).to_have_count(2)
    page.go_back()
    expect(page.locator("[data-page-title]")).to_have_text("Sweeps")
    nav.get_by_role("link", name="Batches").click()
    expect(page.locator(f'[data-batch-list] tr[data-group-id="{batch["id"]}"]')).to_contain_text(
        "ready", timeout=30_000
    )
    shot(page, "batches-list")
