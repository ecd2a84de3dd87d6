"""Every estimator of the scenarios without a file of their own (the air path's, and any new
family's) starts from the New-run form with its defaults and succeeds (the catalog's split:
``tests/frontend/every_estimator.py``)."""

from __future__ import annotations

import httpx
import pytest
from playwright.sync_api import Page

from tests.frontend.every_estimator import (
    estimators_elsewhere,
    runs_from_the_form_with_its_defaults,
)


@pytest.mark.parametrize("estimator", estimators_elsewhere())
def test_every_other_estimator_runs_from_the_form_with_its_defaults(
    page: Page, api: httpx.Client, estimator: str
) -> None:
    runs_from_the_form_with_its_defaults(page, api, estimator)
