"""The ECU view end to end (issue 16): upload the ASAM demo A2L with a HEX image written by
bincopy, find a MAP by searching, see its stored values as a heatmap in its unit with axes
named after its input quantities, "Adapt this map" into a prefilled New run on a log whose
columns carry those quantities (one with INCA's ``\\ETK:1`` suffix), run it, and export the
learned map as CDFX (parsed with xml.etree) and as the patched HEX image (read with bincopy).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import bincopy
import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import plot_data, shot, wait_run
from tests.frontend.ecu_files import (
    MAP_ADDRESS,
    MAP_NAME,
    MAP_UNIT,
    OUTPUT,
    VALUES,
    X_CHANNEL,
    X_POINTS,
    X_QUANTITY,
    Y_POINTS,
    Y_QUANTITY,
    drive_log,
    map_record,
    write_files,
)
from tests.frontend.test_run_view import RUN_URL

pytestmark = [pytest.mark.browser, pytest.mark.slow]

ECU_URL = re.compile(r"/ecus/(\d+)$")
#: Parsing the demo A2L with pya2ldb takes seconds (tens on a busy machine); then it is cached.
PARSE_TIMEOUT_MS = 180_000


def upload_dataset(api, csv: Path) -> dict:
    with csv.open("rb") as f:
        r = api.post("/api/datasets", files={"file": (csv.name, f, "text/csv")})
    assert r.status_code == 201, r.text
    return r.json()


def test_a2l_upload_map_run_and_cdfx_export(page: Page, api, tmp_path: Path) -> None:
    a2l, hex_path, csv = write_files(tmp_path)
    dataset = upload_dataset(api, csv)

    # Upload: the A2L and its HEX image in one form.
    page.goto("/ecus")
    page.locator("#ecu-a2l").set_input_files(str(a2l))
    page.locator("#ecu-values").set_input_files(str(hex_path))
    page.locator("[data-ecu-upload]").click()
    expect(page).to_have_url(ECU_URL, timeout=PARSE_TIMEOUT_MS)
    ecu_id = int(ECU_URL.search(page.url).group(1))
    expect(page.locator("[data-values-format]")).to_have_text("HEX")

    # Browse and search: every MAP of the demo is listed; a search narrows by name.
    page.locator('[data-type="CURVE"]').click()
    page.locator('[data-type="VAL_BLK"]').click()
    expect(page.locator("[data-map-list] [data-map]")).to_have_count(2)
    expect(page).to_have_url(re.compile(r"type=MAP$"))
    page.fill("#ecu-search", "std_axis.std")
    expect(page.locator("[data-map-list] [data-map]")).to_have_count(1)
    page.locator(f'[data-map="{MAP_NAME}"]').click()
    expect(page).to_have_url(re.compile(r"map=ASAM\.C\.MAP\.STD_AXIS\.STD_AXIS"))

    # The map: its stored values as a heatmap, the colour bar in its unit, axes named after
    # the input quantities, the A2L's facts beside it.
    page.locator('[data-plot="ecu-map"] .main-svg').first.wait_for()
    heat = plot_data(page, '[data-plot="ecu-map"]')[0]
    assert heat["type"] == "heatmap"
    assert heat["x"] == list(X_POINTS)
    assert heat["y"] == list(Y_POINTS)
    assert heat["z"] == [list(col) for col in zip(*VALUES, strict=True)]
    expect(page.locator('[data-colorbar-for="ecu-map"] .cbar-title')).to_have_text(MAP_UNIT)
    titles = page.eval_on_selector(
        '[data-plot="ecu-map"]',
        "el => [el.layout.xaxis.title.text, el.layout.yaxis.title.text]",
    )
    assert titles == [f"{X_QUANTITY} [{MAP_UNIT}]", Y_QUANTITY]
    expect(page.locator('[data-fact="limits"]')).to_have_text(f"-32,268 … 32,267 {MAP_UNIT}")
    expect(page.locator('[data-fact="record-layout"]')).to_have_text(
        "RL.MAP.SWORD.SBYTE.SBYTE.INCR"
    )
    shot(page, "ecu-view")
    page.locator("[data-save-base]").click()
    expect(page.locator("[data-toasts]")).to_contain_text("Saved base map #")
    base = api.get("/api/base-maps").json()["items"][0]
    assert base["name"].endswith(MAP_NAME)
    assert base["values"] == [list(row) for row in VALUES]

    # "Adapt this map": New run with the map's grid, units, start values and channels.
    page.locator("[data-adapt]").click()
    expect(page).to_have_url(re.compile(rf"/runs/new\?.*ecu={ecu_id}"))
    banner = page.locator("[data-ecu-banner]")
    expect(banner).to_contain_text(f"Adapting {MAP_NAME}")
    expect(banner).to_contain_text("limits -32,268 … 32,267 hours")
    expect(page.locator(f'[data-quantity="{X_QUANTITY}"]')).to_contain_text(X_CHANNEL)
    expect(page.locator(f'[data-quantity="{Y_QUANTITY}"]')).to_have_attribute(
        "data-matched", "true"
    )
    expect(page.locator("#run-dataset")).to_have_value(str(dataset["id"]))
    expect(page.locator("#axis-0-name")).to_have_value(X_CHANNEL)
    expect(page.locator("#axis-1-name")).to_have_value(Y_QUANTITY)
    expect(page.locator("#axis-0-bp")).to_have_value("-10, 0, 10, 20")
    expect(page.locator("#axis-1-bp")).to_have_value("0, 1, 2, 3, 4")
    expect(page.locator("#axis-0-unit")).to_have_value(MAP_UNIT)
    expect(page.locator("#start-values")).to_be_checked()
    cells = page.locator("[data-values-grid] input[data-cell]")
    expect(cells).to_have_count(20)
    expect(cells.nth(0)).to_have_value(str(VALUES[0][0]))
    expect(cells.nth(19)).to_have_value(str(VALUES[3][4]))
    shot(page, "ecu-new-run")
    page.select_option("#sig-y", OUTPUT)
    page.fill("#cfg-skf-p0", "400")
    page.fill("#cfg-skf-sigma_w", "0.5")
    page.fill("#cfg-skf-sigma_v", "1")
    page.locator("[data-start]").click()

    expect(page).to_have_url(RUN_URL)
    run = wait_run(api, int(RUN_URL.search(page.url).group(1)))
    assert run["status"] == "succeeded", run["error"]
    assert run["table"]["calibration"] == {"ecu_id": ecu_id, "map": MAP_NAME}

    # Export: CDFX and the patched image appear for a linked run.
    page.locator("[data-export-menu]").click()
    with page.expect_download() as download:
        page.locator('[data-export="cdfx"]').click()
    cdfx = ET.parse(download.value.path()).getroot()
    assert cdfx.tag == "MSRSW"
    instance = next(i for i in cdfx.iter("SW-INSTANCE") if i.findtext("SHORT-NAME") == MAP_NAME)
    assert instance.find(".//SW-VALUE-CONT") is not None
    assert instance.find(".//SW-AXIS-CONTS") is not None

    page.locator("[data-export-menu]").click()
    with page.expect_download() as download:
        page.locator('[data-export="image"]').click()
    patched = bincopy.BinFile()
    patched.add_ihex(Path(download.value.path()).read_text())
    record = map_record()
    stored = patched.as_binary(minimum_address=MAP_ADDRESS, padding=b"\x00")[: len(record)]
    values_at = len(record) - 2 * len(X_POINTS) * len(Y_POINTS)
    assert stored[:values_at] == record[:values_at]  # counts and axis points kept
    assert stored[values_at:] != record[values_at:]  # the learned values written


def test_a2l_only_ecu_and_bad_a2l(page: Page, console, tmp_path: Path) -> None:
    """A corrupt A2L is refused with the message next to the A2L field, and no ECU is
    stored; an A2L without values lists its maps but shows no values until a HEX is added."""
    a2l, hex_path, _ = write_files(tmp_path)
    bad = tmp_path / "broken.a2l"
    bad.write_text("/begin PROJECT nonsense")
    console.allow(r"status of 4\d\d")
    page.goto("/ecus")
    page.locator("#ecu-a2l").set_input_files(str(bad))
    page.locator("[data-ecu-upload]").click()
    expect(page.locator("[data-ecu-form] .field-error")).to_be_visible(timeout=PARSE_TIMEOUT_MS)
    expect(page.locator("#ecu-a2l")).to_have_attribute("aria-invalid", "true")
    expect(page).to_have_url(re.compile(r"/ecus$"))

    page.locator("#ecu-a2l").set_input_files(str(a2l))
    page.locator("[data-ecu-upload]").click()
    expect(page).to_have_url(ECU_URL, timeout=PARSE_TIMEOUT_MS)
    ecu_id = int(ECU_URL.search(page.url).group(1))
    expect(page.locator("[data-values-format]")).to_have_text("A2L only")
    page.locator(f'[data-map="{MAP_NAME}"]').click()
    expect(page.locator("[data-no-values]")).to_be_visible()
    expect(page.locator("[data-adapt]")).to_be_visible()
    # Values added later: the open map shows them at once.
    page.locator("#ecu-replace-values").set_input_files(str(hex_path))
    expect(page.locator("[data-values-format]")).to_have_text("HEX")
    page.locator('[data-plot="ecu-map"] .main-svg').first.wait_for()
    assert plot_data(page, '[data-plot="ecu-map"]')[0]["z"][0] == [row[0] for row in VALUES]
    page.goto("/ecus")
    expect(page.locator(f'[data-ecu-list] [data-ecu-id="{ecu_id}"]')).to_contain_text(a2l.stem)
    expect(page.locator("[data-ecu-list] tbody tr", has_text="broken")).to_have_count(0)


def test_adapt_with_an_unmatched_quantity(page: Page, api, tmp_path: Path) -> None:
    """A log that records the Y quantity under another name: the banner lists it with a
    column picker; the picked column keeps the A2L breakpoints, and a reload keeps it."""
    a2l, hex_path, _ = write_files(tmp_path)
    csv = tmp_path / "renamed.csv"
    csv.write_text(drive_log(duration_s=10.0, y_column="gear"))
    dataset = upload_dataset(api, csv)
    with a2l.open("rb") as fa, hex_path.open("rb") as fv:
        r = api.post(
            "/api/ecus",
            files={"a2l": (a2l.name, fa), "values": (hex_path.name, fv)},
            timeout=PARSE_TIMEOUT_MS / 1000,
        )
    assert r.status_code == 201, r.text
    ecu_id = r.json()["id"]

    page.goto(f"/runs/new?dataset={dataset['id']}&ecu={ecu_id}&map={MAP_NAME}")
    unmatched = page.locator(f'[data-quantity="{Y_QUANTITY}"]')
    expect(unmatched).to_have_attribute("data-matched", "false")
    expect(unmatched).to_contain_text("has no channel of its name")
    expect(page.locator("#axis-0-name")).to_have_value(X_CHANNEL)
    page.select_option("#ecu-axis-1", "gear")
    expect(page.locator("#axis-1-name")).to_have_value("gear")
    expect(page.locator("#axis-1-bp")).to_have_value("0, 1, 2, 3, 4")
    expect(page.locator("#start-values")).to_be_checked()
    expect(page).to_have_url(re.compile(r"axes=.*,gear"))

    page.reload()
    expect(page.locator("#ecu-axis-1")).to_have_value("gear")
    expect(page.locator("#axis-1-name")).to_have_value("gear")
    expect(page.locator("#axis-1-bp")).to_have_value("0, 1, 2, 3, 4")
