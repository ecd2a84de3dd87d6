"""Datasets view, multi-rate upload: an MDF4 written by asammdf (1 kHz, 10 ms and 100 ms
groups, a value table, a ±inf rational conversion) uploaded on a chosen raster and a chosen
set of channels; the dataset shows its rows, rate, ingest's notes and the masked samples
per channel (`docs/data-formats.md#multi-rate`)."""

from __future__ import annotations

import re
import uuid
from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import shot, wait_run
from tests.frontend.conftest import Console
from tests.support.helpers import log_csv
from tests.support.measurements import NMOT, POLE, POLE_RAW, T100, write_measurement

pytestmark = [pytest.mark.browser, pytest.mark.slow]

# The 10 ms grid over the span every group covers (0.02 … 1.92 s): 191 rows at 100 Hz.
ROWS_10MS = 191
POLE_MASKED = int((POLE_RAW == 10).sum())  # the samples at the pole, -inf after conversion
LAMBDA_MASKED = 3  # NaN, +inf and one flagged invalid


def _dataset(api, name: str) -> dict:
    items = api.get("/api/datasets", params={"limit": 500}).json()["items"]
    return next(d for d in items if d["name"] == name)


def _upload(page: Page, path: Path, name: str, *, raster: str = "", channels: str = "") -> None:
    page.goto("/datasets")
    expect(page.get_by_role("heading", name="Datasets", exact=True)).to_be_visible()
    page.set_input_files("#upload-file", str(path))
    page.fill("#upload-name", name)
    page.get_by_label("Raster", exact=True).fill(raster)
    page.get_by_label("Channels to keep").fill(channels)
    page.get_by_role("button", name="Upload").click()
    progress = page.get_by_role("progressbar", name="Upload progress")
    expect(progress).to_have_attribute("aria-valuenow", "100", timeout=30_000)


def test_a_multi_rate_mdf4_on_a_10ms_raster_shows_rows_rate_and_masked_samples(
    page: Page, api, tmp_path: Path
) -> None:
    measurement = write_measurement(tmp_path)
    name = f"multirate-{uuid.uuid4().hex[:8]}"
    _upload(page, measurement.path, name, raster="10ms")

    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    expect(row).to_have_attribute("aria-current", "true", timeout=20_000)
    expect(row.locator("td").nth(2)).to_have_text(str(ROWS_10MS))
    expect(row.locator("td").nth(3)).to_have_text("100 Hz")
    expect(row.locator("[data-masked-total]")).to_have_text(f"{POLE_MASKED + LAMBDA_MASKED} masked")

    report = page.locator("[data-ingest-report]")
    expect(report).to_contain_text("onto the 10 ms raster (191 rows")
    expect(report).to_contain_text(f"channel {POLE!r}: {POLE_MASKED} of 200 samples masked")
    pole = page.locator(f'[data-channel="{POLE}"]')
    expect(pole).to_contain_text("[1/s]")
    expect(pole.locator("[data-masked]")).to_have_attribute("data-masked", str(POLE_MASKED))
    expect(page.locator('[data-channel="fast"] [data-masked]')).to_have_count(0)
    shot(page, "datasets-multirate")

    # What the view shows is what the API stored.
    stored = api.get(f"/api/datasets/{_dataset(api, name)['id']}").json()
    assert (stored["rows"], round(stored["rate_hz"], 6)) == (ROWS_10MS, 100.0)
    assert stored["masked"] == {POLE: POLE_MASKED, "lambda": LAMBDA_MASKED}

    # Reloaded from the API alone (no upload answer in memory), the same report is shown.
    page.reload()
    expect(page.locator(f'[data-channel="{POLE}"] [data-masked]')).to_have_attribute(
        "data-masked", str(POLE_MASKED)
    )
    expect(page.locator("[data-ingest-report]")).to_contain_text(f"{POLE_MASKED} of 200")


def test_kept_channels_default_to_the_slowest_raster(page: Page, api, tmp_path: Path) -> None:
    measurement = write_measurement(tmp_path)
    name = f"kept-{uuid.uuid4().hex[:8]}"
    _upload(page, measurement.path, name, channels=f"fast, {NMOT}")

    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    expect(row).to_have_attribute("aria-current", "true", timeout=20_000)
    expect(row.locator("td").nth(2)).to_have_text(str(T100.size))  # the 100 ms timestamps
    expect(row.locator("td").nth(3)).to_have_text("10 Hz")
    expect(row.locator("[data-masked-total]")).to_have_count(0)
    expect(page.locator("[data-channel]")).to_have_count(2)
    expect(page.locator("[data-ingest-report]")).to_contain_text(
        f"raster of channel {NMOT!r} ({T100.size} rows"
    )


def test_a_bad_raster_is_refused_next_to_its_field(
    page: Page, console: Console, tmp_path: Path
) -> None:
    console.allow(r"status of 422")
    measurement = write_measurement(tmp_path)
    _upload(page, measurement.path, f"bad-{uuid.uuid4().hex[:8]}", raster="fast please")
    raster = page.get_by_label("Raster", exact=True)
    expect(raster).to_have_attribute("aria-invalid", "true")
    expect(page.locator(".field-error")).to_contain_text("raster 'fast please' is not understood")


def test_new_run_offers_the_raster_on_a_dataset_stored_as_recorded(
    page: Page, api, console: Console, tmp_path: Path
) -> None:
    """On a dataset stored as recorded the run options have a Raster field listing the
    channels' own steps; *Run again…* brings a run's raster back, a new one is sent as
    config.raster and the run reads on it; a refused raster is named next to the field; on a
    dataset on one time base the field is not offered."""
    measurement = write_measurement(tmp_path)
    name = f"recorded-{uuid.uuid4().hex[:8]}"
    _upload(page, measurement.path, name)
    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    expect(row).to_have_attribute("aria-current", "true", timeout=20_000)
    dataset = _dataset(api, name)
    assert dataset["recorded"] is True
    body = {
        "dataset_id": dataset["id"],
        "estimator": "skf",
        "signals": {"y": POLE},
        "table": {
            "axes": [
                {"name": "mode", "breakpoints": [0.0, 1.0, 2.0]},
                {"name": "status", "breakpoints": [0.0, 3.0, 6.0, 9.0, 12.0]},
            ]
        },
        "config": {"sigma_w": 0.01, "sigma_v": 0.05, "p0": 10.0, "raster": f"channel:{NMOT}"},
    }
    created = api.post("/api/runs", json=body)
    assert created.status_code == 201, created.text
    source = wait_run(api, created.json()["id"])
    assert source["metrics"]["raster_s"] == pytest.approx(0.1)

    page.goto(f"/runs/new?from={source['id']}")
    raster = page.locator("#run-raster")
    expect(raster).to_be_visible()
    expect(raster).to_have_value(f"channel:{NMOT}")
    expect(page.locator("#run-raster-help")).to_contain_text(f"{NMOT} 100 ms")
    expect(page.locator("#run-raster-help")).to_contain_text("fast 1 ms")

    console.allow(r"status of 422")
    raster.fill("fast please")
    page.locator("[data-start]").click()
    expect(raster).to_have_attribute("aria-invalid", "true")
    expect(page.locator(".field-error")).to_contain_text("not understood")

    raster.fill("50ms")
    with page.expect_request(lambda r: r.url.endswith("/api/runs") and r.method == "POST") as r:
        page.locator("[data-start]").click()
    assert r.value.post_data_json["config"]["raster"] == "50ms"
    page.wait_for_url(re.compile(r"/runs/\d+$"))
    run_id = int(page.url.rsplit("/", 1)[1])
    assert wait_run(api, run_id)["metrics"]["raster_s"] == pytest.approx(0.05)

    # A dataset on one time base: nothing to choose.
    dense = api.post(
        "/api/datasets",
        files={"file": ("dense.csv", log_csv(200).encode())},
        data={"name": f"dense-{uuid.uuid4().hex[:8]}"},
    )
    assert dense.status_code == 201, dense.text
    assert dense.json()["recorded"] is False
    page.goto(f"/runs/new?dataset={dense.json()['id']}")
    expect(page.locator("#run-pace")).to_be_visible()
    expect(page.locator("[data-run-raster]")).to_be_hidden()
