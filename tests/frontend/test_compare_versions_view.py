"""Compare and Versions: several estimators started at once and compared (final maps,
differences, overlaid errors, sortable metrics); the run's versions timeline (scrub, play);
two versions diffed, labelled and exported (the downloaded file checked)."""

from __future__ import annotations

import json
import re
import uuid

from playwright.sync_api import Page, expect

from tests.frontend.browser import plot_data, shot, upload_example, wait_run
from tests.frontend.test_run_view import heatmap_z, run_form_url
from tests.support.server import run_body

GRID = {
    "axes": [
        {"name": "speed_rpm", "breakpoints": [500, 1000, 1500, 2000, 2500, 3000, 3500, 4000, 4500]},
        {"name": "fuel_mg_per_stroke", "breakpoints": [0, 10, 20, 30, 40, 50, 60, 70]},
    ]
}


def start_run(api, dataset_id: int, estimator: str, **config) -> dict:
    body = {
        "dataset_id": dataset_id,
        "estimator": estimator,
        "signals": {"y": "nox_ppm"},
        "table": GRID,
        "config": {"theta0": 300, "p0": 1e4, "sigma_w": 5, "sigma_v": 50, **config},
    }
    r = api.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    return r.json()


def number(text: str) -> float:
    return float(re.match(r"-?[\d,.]+(e-?\d+)?", text.strip()).group(0).replace(",", ""))


def test_compare_two_estimators_started_together(page: Page, api) -> None:
    dataset = upload_example(api, f"compare-{uuid.uuid4().hex[:8]}")
    page.goto(run_form_url(dataset["id"]))
    page.check("#est-kf")
    start = page.locator("[data-start]")
    expect(start).to_have_text("Start 2 runs")
    page.select_option("#run-pace", "50")
    start.click()
    expect(page).to_have_url(re.compile(r"/compare\?runs=\d+,\d+$"))
    ids = [int(i) for i in page.url.split("runs=")[1].split(",")]
    for run_id in ids:
        wait_run(api, run_id)
    table = page.locator("[data-metrics-table]")
    expect(table.locator("tbody tr", has_text="succeeded")).to_have_count(2, timeout=30_000)

    # Final maps (one colour scale), one difference map, errors overlaid.
    expect(page.locator('[data-plot^="final-"]')).to_have_count(2)
    for run_id in ids:
        expect(page.locator(f'[data-plot="final-{run_id}"] .main-svg').first).to_be_attached()
    expect(page.locator('[data-plot^="diff-"]')).to_have_count(1)
    ranges = [
        page.eval_on_selector(
            f'[data-plot="final-{i}"]', "el => [el.data[0].zmin, el.data[0].zmax]"
        )
        for i in ids
    ]
    assert ranges[0] == ranges[1]
    page.wait_for_function(
        "() => document.querySelector('[data-plot=\"errors\"]')?.data?.length === 2"
    )
    names = {t["name"] for t in plot_data(page, '[data-plot="errors"]')}
    runs = {r["id"]: r for r in (api.get(f"/api/runs/{i}").json() for i in ids)}
    assert names == {f"#{i} {runs[i]['estimator']}" for i in ids}

    # Sortable metrics table.
    rmse = {i: runs[i]["metrics"]["output_rmse"] for i in ids}
    header = page.locator('th:has([data-sort="m:output_rmse"])')
    for direction, reverse in (("ascending", False), ("descending", True)):
        page.locator('[data-sort="m:output_rmse"]').click()
        expect(header).to_have_attribute("aria-sort", direction)
        order = [
            int(x)
            for x in table.locator("tbody tr").evaluate_all(
                "rows => rows.map(r => r.dataset.runId)"
            )
        ]
        assert order == sorted(ids, key=lambda i: rmse[i], reverse=reverse)
    best = min(ids, key=lambda i: rmse[i])
    expect(table.locator(f'tr[data-run-id="{best}"] td.best').first).to_be_visible()
    shot(page, "compare")


def test_scrub_and_play_versions_then_label_and_export(page: Page, api, tmp_path) -> None:
    dataset = upload_example(api, f"versions-{uuid.uuid4().hex[:8]}")
    run = start_run(api, dataset["id"], "skf", version_every={"samples": 1500})
    wait_run(api, run["id"])
    versions = api.get(f"/api/runs/{run['id']}/versions").json()["items"]
    assert len(versions) >= 5

    # Timeline on the run page: the slider scrubs, the play button animates.
    page.goto(f"/runs/{run['id']}")
    where = page.locator("[data-version-where]")
    expect(where).to_contain_text(f"version {len(versions)} of {len(versions)}")
    final_z = heatmap_z(page, '[data-plot="map"]')
    slider = page.locator("[data-version-slider]")
    slider.focus()
    page.keyboard.press("Home")
    expect(where).to_contain_text(f"version 1 of {len(versions)}")
    page.wait_for_function(
        "z => JSON.stringify(document.querySelector('[data-plot=\"map\"]').data[0].z) !== z",
        arg=json.dumps(final_z),
    )
    first = api.get(f"/api/runs/{run['id']}/versions/{versions[0]['id']}").json()
    z = heatmap_z(page, '[data-plot="map"]')
    assert z[0] == [row[0] for row in first["values"]]  # rows of the plot are the 2nd axis
    page.keyboard.press("ArrowRight")
    expect(where).to_contain_text(f"version 2 of {len(versions)}")
    page.locator("[data-play]").click()
    expect(page.locator("[data-play]")).to_have_attribute("aria-label", "Pause")
    expect(where).to_contain_text(f"version 3 of {len(versions)}")
    expect(where).to_contain_text(f"version {len(versions)} of {len(versions)}", timeout=20_000)
    expect(page.locator("[data-play]")).to_have_attribute("aria-label", "Play the map's evolution")

    # Versions view: A = first, B = final; their difference; label B; export both.
    a, b = versions[0], versions[-1]
    page.goto(f"/versions?a={run['id']}:{a['number']}&b={run['id']}:{b['number']}")
    doc_a = first
    doc_b = api.get(f"/api/runs/{run['id']}/versions/{b['id']}").json()
    max_diff = max(
        abs(vb - va)
        for ra, rb in zip(doc_a["values"], doc_b["values"], strict=True)
        for va, vb in zip(ra, rb, strict=True)
    )
    stat = page.locator('[data-stat="max"]')
    expect(stat).to_contain_text("ppm")
    assert abs(number(stat.inner_text()) - max_diff) <= 5e-4 * max_diff
    expect(page.locator('[data-plot="diff"] .main-svg').first).to_be_attached()

    page.fill("#label-b", "release candidate")
    page.locator('[data-save-label="b"]').click()
    expect(page.locator("#version-b option:checked")).to_contain_text("release candidate")
    labelled = api.get(f"/api/runs/{run['id']}/versions").json()["items"][-1]
    assert labelled["label"] == "release candidate"

    page.select_option("#format-b", "json")
    with page.expect_download() as download:
        page.locator('[data-export="b"]').click()
    path = tmp_path / download.value.suggested_filename
    download.value.save_as(path)
    exported = json.loads(path.read_text())
    assert [ax["name"] for ax in exported["axes"]] == ["speed_rpm", "fuel_mg_per_stroke"]
    assert exported["values"] == doc_b["values"]

    page.select_option("#format-a", "csv")
    with page.expect_download() as download:
        page.locator('[data-export="a"]').click()
    csv_path = tmp_path / download.value.suggested_filename
    download.value.save_as(csv_path)
    lines = csv_path.read_text().splitlines()
    assert lines[0].startswith("speed_rpm [rpm]")
    assert len(lines) == 1 + len(GRID["axes"][0]["breakpoints"])
    first_row = [float(v) for v in lines[1].split(",")[1:]]
    assert first_row == doc_a["values"][0]

    shot(page, "versions")
    page.reload()
    expect(page.locator("#version-a")).to_have_value(str(a["number"]))
    expect(page.locator("#version-b")).to_have_value(str(b["number"]))


def _bar_log(n: int = 2000) -> str:
    """``u1 [rpm], u2 [mg/stroke], y`` over the 4×4 grid of ``run_body``, ``y`` a few bar."""
    rows = ["time [s],u1 [rpm],u2 [mg/stroke],y"]
    for k in range(n):
        u1, u2 = 500 + (k * 37) % 3000, (k * 11) % 60
        rows.append(f"{k / 50},{u1},{u2},{1 + u1 / 1000 + u2 / 100 + (k % 7) / 100}")
    return "\n".join(rows) + "\n"


def test_runs_of_different_quantities_get_their_own_scale_and_best(page: Page, api) -> None:
    """NOx runs in ppm beside a run whose output is in bar: each quantity has its own colour
    scale and its own best, never a bar error "better" than a ppm one."""
    dataset = upload_example(api, f"mixed-{uuid.uuid4().hex[:8]}")
    ppm = [start_run(api, dataset["id"], e)["id"] for e in ("skf", "kf")]
    other = api.post(
        "/api/datasets",
        files={"file": ("bar.csv", _bar_log(), "text/csv")},
        data={"name": f"bar-{uuid.uuid4().hex[:8]}", "units": json.dumps({"y": "bar"})},
    )
    assert other.status_code == 201, other.text
    created = api.post("/api/runs", json=run_body(other.json()["id"], "skf"))
    assert created.status_code == 201, created.text
    bar = created.json()["id"]
    for run_id in (*ppm, bar):
        wait_run(api, run_id)
    page.goto(f"/compare?runs={ppm[0]},{ppm[1]},{bar}")
    expect(
        page.get_by_role("heading", name="Final maps · one colour scale per quantity")
    ).to_be_visible()
    for run_id in (*ppm, bar):
        expect(page.locator(f'[data-plot="final-{run_id}"] .main-svg').first).to_be_attached()
    ranges = {
        i: page.eval_on_selector(
            f'[data-plot="final-{i}"]', "el => [el.data[0].zmin, el.data[0].zmax]"
        )
        for i in (*ppm, bar)
    }
    assert ranges[ppm[0]] == ranges[ppm[1]] != ranges[bar]
    table = page.locator("[data-metrics-table]")
    expect(table.locator("tbody tr", has_text="succeeded")).to_have_count(3, timeout=30_000)
    best = dict(
        table.evaluate(
            """t => {
              const head = [...t.tHead.rows[0].cells];
              const i = head.findIndex((c) => c.querySelector('[data-sort="m:output_rmse"]'));
              return [...t.tBodies[0].rows].map((r) => [
                Number(r.dataset.runId), r.cells[i].classList.contains("best")]);
            }"""
        )
    )
    assert best[bar] is False  # alone in bar: nothing to be better than
    assert [best[i] for i in ppm].count(True) == 1, best
