"""Editing a finished run's map in the run view: cells picked on the map plot and in the cell
grid (click, shift-click, drag, keyboard), smoothed, undone and redone (buttons and
Ctrl+Z / Ctrl+Y), one locked and the others reset to the run's base map (θ0), then saved as
a labelled version (a base map, docs/dashboard.md), which the API returns with the edited
values, the run and version as its lineage and the edit log; then accepted, set and rejected
(back to θ0) and the reject undone."""

from __future__ import annotations

import uuid

import numpy as np
from playwright.sync_api import Page, expect

from tests.frontend.browser import shot, upload_example, wait_run
from tests.frontend.test_compare_versions_view import start_run
from tests.frontend.test_map_edit_ops import smooth_reference
from tests.frontend.test_run_view import heatmap_z

THETA0 = 300.0
PANEL = "[data-edit-panel]"


def shown_values(page: Page) -> np.ndarray:
    """The map plot's values as a table (axis 0 first): the heatmap's z transposed."""
    z = heatmap_z(page, '[data-plot="map"]')
    assert z is not None
    return np.array(z, dtype=float).T


def cell(page: Page, k: int):  # type: ignore[no-untyped-def]
    return page.locator(f'{PANEL} td[data-cell="{k}"]')


def click_map_cell(page: Page, x: float, y: float) -> None:
    """Click the map plot at breakpoint (x, y)."""
    page.locator('[data-plot="map"]').scroll_into_view_if_needed()
    px, py = page.eval_on_selector(
        '[data-plot="map"]',
        """(el, [x, y]) => {
          const xa = el._fullLayout.xaxis, ya = el._fullLayout.yaxis;
          const r = el.getBoundingClientRect();
          return [r.left + xa._offset + xa.l2p(x), r.top + ya._offset + ya.l2p(y)];
        }""",
        [x, y],
    )
    page.mouse.move(px - 3, py - 3)
    page.mouse.click(px, py)


def test_edit_a_learned_map_and_save_it_as_a_base_map(page: Page, api) -> None:
    dataset = upload_example(api, f"edit-{uuid.uuid4().hex[:8]}")
    run = start_run(api, dataset["id"], "skf")
    assert wait_run(api, run["id"])["status"] == "succeeded"
    summary = api.get(f"/api/runs/{run['id']}/versions").json()["items"][-1]
    version = api.get(f"/api/runs/{run['id']}/versions/{summary['id']}").json()
    learned = np.array(version["values"], dtype=float)
    n1 = learned.shape[1]
    bp0 = version["axes"][0]["breakpoints"]
    bp1 = version["axes"][1]["breakpoints"]
    k = lambda i, j: i * n1 + j  # noqa: E731 - flat index, row-major

    page.goto(f"/runs/{run['id']}")
    start = page.locator("[data-edit-start]")
    expect(start).to_be_enabled()
    expect(page.locator('[data-plot="map"] .main-svg').first).to_be_attached()
    start.click()
    expect(page.locator(PANEL)).to_be_visible()
    expect(page.locator("[data-edit-base]")).to_contain_text("θ0 = 300")
    np.testing.assert_array_equal(shown_values(page), learned)

    # A click on the map plot selects its cell.
    click_map_cell(page, bp0[6], bp1[1])
    expect(cell(page, k(6, 1))).to_have_attribute("aria-selected", "true")
    expect(page.locator("[data-edit-status]")).to_contain_text("1 selected")

    # Click and shift-click in the grid: a 3 × 3 rectangle; smooth it.
    cell(page, k(2, 3)).click()
    cell(page, k(4, 5)).click(modifiers=["Shift"])
    rect = {k(i, j) for i in range(2, 5) for j in range(3, 6)}
    expect(page.locator(f'{PANEL} td[aria-selected="true"]')).to_have_count(9)
    page.locator('[data-edit-op="smooth"]').click()
    smoothed = smooth_reference(learned, rect, set())
    np.testing.assert_allclose(shown_values(page), smoothed, rtol=1e-12)
    outlines = page.eval_on_selector(
        '[data-plot="map"]', "el => el.data.filter(t => t.name === 'outlined cells').length"
    )
    assert outlines == 1  # the selection outlined on the map

    # Undo / redo: buttons, then the keyboard.
    page.locator("[data-edit-undo]").click()
    np.testing.assert_array_equal(shown_values(page), learned)
    page.locator("[data-edit-redo]").click()
    np.testing.assert_allclose(shown_values(page), smoothed, rtol=1e-12)
    cell(page, k(2, 3)).focus()
    page.keyboard.press("Control+z")
    np.testing.assert_array_equal(shown_values(page), learned)
    page.keyboard.press("Control+y")
    np.testing.assert_allclose(shown_values(page), smoothed, rtol=1e-12)
    expect(page.locator("[data-edit-redo]")).to_be_disabled()

    # Lock the centre with the keyboard (arrows move, space selects, L locks).
    cell(page, k(2, 3)).click()
    page.keyboard.press("ArrowDown")
    page.keyboard.press("ArrowRight")
    page.keyboard.press("Enter")
    expect(page.locator(f'{PANEL} td[aria-selected="true"]')).to_have_count(1)
    page.keyboard.press("l")
    expect(cell(page, k(3, 4))).to_have_attribute("data-locked", "")

    # Drag over the rectangle and reset it to the base map: the locked cell keeps its value.
    first = cell(page, k(2, 3)).bounding_box()
    last = cell(page, k(4, 5)).bounding_box()
    assert first is not None
    assert last is not None
    page.mouse.move(first["x"] + 5, first["y"] + 5)
    page.mouse.down()
    page.mouse.move(last["x"] + 5, last["y"] + 5, steps=6)
    page.mouse.up()
    expect(page.locator(f'{PANEL} td[aria-selected="true"]')).to_have_count(9)
    page.locator('[data-edit-op="reset"]').click()
    expected = smoothed.copy()
    for c in rect - {k(3, 4)}:
        expected.flat[c] = THETA0
    edited = shown_values(page)
    np.testing.assert_allclose(edited, expected, rtol=1e-12)
    assert edited[3, 4] == smoothed[3, 4] != learned[3, 4]
    expect(page.locator("[data-edit-status]")).to_contain_text("1 locked")
    shot(page, "map-edit")

    # Save as a labelled version (a base map, docs/dashboard.md): the form shows its lineage
    # first; the API has the edited grid, its lineage and the edits.
    lineage_note = page.locator("[data-edit-lineage]")
    expect(lineage_note).to_contain_text(f"run {run['id']}, v{version['number']}, 3 edit(s)")
    expect(lineage_note).to_contain_text("smooth, lock, reset")
    expect(page.locator("[data-edit-save]")).to_have_text("Save as version…")
    page.fill("#edit-name", "NOx map, edited")
    page.locator("[data-edit-save]").click()
    saved = page.locator("[data-edit-saved]")
    expect(saved).to_contain_text("Saved version “NOx map, edited” (base map #")
    expect(saved).to_contain_text(f"lineage: run {run['id']}, v{version['number']}, 3 edit(s)")
    base_id = int(saved.get_attribute("data-edit-saved") or 0)
    base = api.get(f"/api/base-maps/{base_id}").json()
    assert base["name"] == "NOx map, edited"
    assert base["source"] == "edit"
    np.testing.assert_array_equal(np.array(base["values"]), edited)
    lineage = base["lineage"]
    assert lineage["run_id"] == run["id"]
    assert lineage["version_id"] == version["id"]
    ops = [e["op"] for e in lineage["config"]["edits"]]
    assert ops == ["smooth", "lock", "reset"]
    assert lineage["config"]["edits"][1]["cells"] == [k(3, 4)]
    listing = api.get("/api/base-maps", params={"limit": 500}).json()["items"]
    assert base_id in [m["id"] for m in listing]

    # Accept with nothing selected: every unlocked cell back to the learned value.
    cell(page, k(0, 0)).focus()
    page.keyboard.press("Escape")
    expect(page.locator("[data-edit-status]")).to_contain_text("0 selected")
    page.locator('[data-edit-op="accept"]').click()
    accepted = learned.copy()
    accepted[3, 4] = smoothed[3, 4]
    np.testing.assert_array_equal(shown_values(page), accepted)

    # Shift+arrows extend a rectangle from the focused cell; Set types a value into it.
    cell(page, k(0, 0)).click()
    for key in ("Shift+ArrowRight", "Shift+ArrowRight", "Shift+ArrowDown"):
        page.keyboard.press(key)
    expect(page.locator(f'{PANEL} td[aria-selected="true"]')).to_have_count(6)
    page.fill("#edit-set-value", "123.5")
    page.locator('[data-edit-op="set"]').click()
    accepted[0:2, 0:3] = 123.5
    np.testing.assert_array_equal(shown_values(page), accepted)

    # Reject on the selection: its cells back to the base map (θ0), the rest as they were;
    # Undo brings the typed values back.
    expect(page.locator(f'{PANEL} td[aria-selected="true"]')).to_have_count(6)
    page.locator('[data-edit-op="reject"]').click()
    rejected = accepted.copy()
    rejected[0:2, 0:3] = THETA0
    np.testing.assert_array_equal(shown_values(page), rejected)
    expect(page.locator("[data-edit-lineage]")).to_contain_text("accept, set, reject)")
    page.locator("[data-edit-undo]").click()
    np.testing.assert_array_equal(shown_values(page), accepted)

    # Closing the editor shows the stored version again.
    page.locator("[data-edit-discard]").click()
    expect(page.locator(PANEL)).to_be_hidden()
    np.testing.assert_array_equal(shown_values(page), learned)
