"""Every registered estimator starts from the New-run form with its defaults and succeeds:
here the estimators of the NOx-map scenario, and the scenario's setup on the form.

For each estimator (``tests/frontend/every_estimator.py`` splits the catalog over this file,
``test_every_estimator_torque.py`` and ``test_every_estimator_others.py``, each with its own
server) a short dataset is simulated from a scenario it applies to (one per scenario, shared
by the estimators of a family); the form is opened on /runs/new, the dataset and the
estimator are picked, and it is submitted untouched: the catalog's defaults with the
scenario's setup (on by default for a simulated dataset: its grid, signals and settings). The
run must reach ``succeeded`` and the pages log no console error.
"""

from __future__ import annotations

import re

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.frontend.every_estimator import (
    MAPS,
    estimators_on,
    pick,
    runs_from_the_form_with_its_defaults,
    scenario_for,
    simulated,
)


@pytest.mark.parametrize("estimator", estimators_on(MAPS))
def test_every_estimator_runs_from_the_form_with_its_defaults(
    page: Page, api: httpx.Client, estimator: str
) -> None:
    runs_from_the_form_with_its_defaults(page, api, estimator)


def test_the_scenario_setup_fills_grid_signals_and_settings(page: Page, api: httpx.Client) -> None:
    """On a NOx scenario the SKF form shows the scenario's grid and its paper settings, each
    field saying where its value comes from; off, the catalog's defaults come back."""
    dataset = simulated(api, scenario_for("skf"))
    setup = api.get(f"/api/datasets/{dataset['id']}/setup").json()["estimators"]["skf"]
    pick(page, dataset["id"], "skf")
    axes = setup["table"]["axes"]
    expect(page.locator("#axis-0-bp")).to_have_value(re.compile(rf"^{axes[0]['breakpoints'][0]:g}"))
    field = page.locator('[data-config="skf"] [data-key="sigma_w"]')
    expect(field.locator("input")).to_have_value(f"{setup['config']['sigma_w']:g}")
    expect(field.locator("[data-source]")).to_contain_text("scenario")
    page.uncheck("#run-use-setup")
    catalog = {e["name"]: e for e in api.get("/api/estimators").json()["items"]}
    expect(page.locator("#cfg-skf-sigma_w")).to_have_value(
        f"{catalog['skf']['defaults']['sigma_w']:g}"
    )
    expect(page.locator('[data-config="skf"] [data-key="sigma_w"] [data-source]')).to_be_visible()
