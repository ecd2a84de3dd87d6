"""Every metric key a run stores has a name and a formula in the dashboard: the truth-free
checks of estimation/holdout_observers.py and holdout_ekf.py (per-output held-out error and
NIS, the LPV observer's output-error statistics) and the checks an estimator has no honest form of
(``…:not_applicable:<reason>``, stored as null), which would otherwise show as raw keys."""

from __future__ import annotations

import uuid

from playwright.sync_api import Page, expect

from tests.frontend.browser import upload_example, wait_run
from tests.frontend.test_compare_versions_view import start_run

KEYS = [
    "holdout:rmse",
    "holdout:p_im_rmse",
    "nis:mean_band_low",
    "nis:mean_band_high",
    "nis:p_im_mean",
    "residual:mean",
    "residual:rms",
    "residual:mean_over_rms",
    "residual:autocorr_lag1",
    "residual:autocorr_band",
    "holdout:not_applicable:unmeasured_input",
    "nis:not_applicable:no_innovation_covariance",
]


def test_every_truth_free_metric_key_has_a_name_and_a_formula(page: Page) -> None:
    page.goto("/datasets")
    named = page.evaluate(
        """async keys => {
            const m = await import("/static/js/metric-names.js");
            return keys.map(k => [k, m.metricName(k), m.metricFormula(k, {})]);
        }""",
        KEYS,
    )
    for key, name, formula in named:
        # A name, not the raw key: no "prefix:" and no snake_case outside the output's name.
        assert not name.startswith(("holdout:", "nis:", "residual:")), (key, name)
        assert "_" not in name.split(",")[0].split("(")[0], (key, name)
        assert formula, key
    names = {key: name for key, name, _ in named}
    assert names["holdout:p_im_rmse"] == "Held-out RMSE, p_im"
    assert names["nis:p_im_mean"] == "Mean NIS, p_im"
    assert names["holdout:not_applicable:unmeasured_input"] == (
        "Held-out error: n/a (unmeasured input)"
    )
    assert names["nis:not_applicable:no_innovation_covariance"] == (
        "NIS: n/a (no innovation covariance)"
    )


def test_a_mean_nis_outside_its_band_says_which_way(page: Page, api) -> None:  # type: ignore[no-untyped-def]
    """σv twenty times the NOx sensor's noise: the filter is too cautious, its mean NIS
    falls below the 95 % band, and the card says so (docs/tuning.md#innovations)."""
    dataset = upload_example(api, f"nis-{uuid.uuid4().hex[:8]}")
    run = wait_run(api, start_run(api, dataset["id"], "skf", sigma_v=1000)["id"])
    metrics = run["metrics"]
    assert metrics["nis:mean"] < metrics["nis:mean_band_low"], metrics  # the premise
    page.goto(f"/runs/{run['id']}")
    card = page.locator('[data-metric="nis:mean"]')
    expect(card.locator("[data-nis-verdict]")).to_contain_text("below: too cautious")
