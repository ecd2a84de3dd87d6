"""Loading each dashboard view in a fresh browser context, cold then warm, and when its
content and first plot appear: shared by the view tests (that every view renders, and that
warm loads come from the cache) and ``scripts/bench_dashboard.py`` (how long it takes)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from playwright.sync_api import Browser, Page

from tests.frontend.browser import VIEWPORT

JS = Path(__file__).parent / "js"

# The view's own content (what the first render shows) and its first plot, per view.
READY = {
    "datasets": ("[data-dataset-list] table", "[data-channel] .main-svg"),
    "new-run": ("[data-run-form] [data-axes] .axis-row", "[data-run-form] .main-svg"),
    "run": ("[data-metrics] .metric", '[data-plot="map"] .main-svg'),
    "compare": ("[data-metrics-table] tbody tr", '[data-plot^="final-"] .main-svg'),
    "versions": ("[data-diff-stats] dl", '[data-plot="diff"] .main-svg'),
}

# Records when a selector first matches (performance.now(): ms since the navigation
# started), watched from the moment the document exists.
WATCH = (JS / "watch_first_render.js").read_text()
LOAD_TIMES = (JS / "load_times.js").read_text()


def views(run: dict) -> list[tuple[str, str, str]]:
    """(name, URL, page title) of every view, showing the finished ``run`` and its dataset."""
    rid, did = run["id"], run["dataset_id"]
    return [
        ("datasets", f"/datasets?id={did}", "Datasets"),
        (
            "new-run",
            f"/runs/new?dataset={did}&estimator=skf&signals=y:nox_ppm&axes=speed_rpm,fuel_mg_per_stroke",
            "New run",
        ),
        ("run", f"/runs/{rid}", run["name"]),
        ("compare", f"/compare?runs={rid}", "Compare 1 run"),
        ("versions", f"/versions?a={rid}", "Versions"),
    ]


@dataclass(frozen=True)
class Load:
    """One navigation: milliseconds from its start to DOMContentLoaded, to the view's
    content and to its first plot, and the bytes it transferred."""

    view: str
    attempt: str  # "cold" (empty cache) or "warm"
    dcl_ms: float
    content_ms: float
    plot_ms: float
    bytes: int


def measure_loads(
    browser: Browser,
    base_url: str,
    run: dict,
    *,
    warm: int = 2,
    on_page: Callable[[Page], None] | None = None,
) -> list[Load]:
    """Each view in its own new context (empty cache): one cold load, then ``warm`` reloads."""
    loads = []
    for name, url, _title in views(run):
        context = browser.new_context(base_url=base_url, viewport=VIEWPORT)
        try:
            page = context.new_page()
            if on_page is not None:
                on_page(page)
            page.add_init_script(f"({WATCH.strip().rstrip(';')})({list(READY[name])!r})")
            for attempt in ["cold"] + ["warm"] * warm:
                if attempt == "cold":
                    page.goto(url)
                else:
                    page.reload()
                page.wait_for_function(
                    "() => window.__seen.content !== null && window.__seen.plot !== null",
                    timeout=30_000,
                )
                t = page.evaluate(LOAD_TIMES)
                loads.append(
                    Load(name, attempt, t["dcl"], t["content"], t["plot"], int(t["bytes"]))
                )
        finally:
            context.close()
    return loads
