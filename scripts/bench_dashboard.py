"""Dashboard page-load benchmark (figures for the README; not a test).

Against a real ``mapwise serve`` on a temporary SQLite database, with the bundled NOx log
and one finished SKF run: each view is opened ``--rounds`` times in a fresh Debian Chromium
context (empty cache, so the first load fetches and compiles Plotly.js) and then reloaded
``--warm`` times. For each view: milliseconds from the start of the navigation to
DOMContentLoaded, to the view's own content and to its first plot, as the median (and the
worst) over the rounds, cold and warm apart.

    .venv/bin/python scripts/bench_dashboard.py [--rounds 5] [--warm 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from playwright.sync_api import sync_playwright  # noqa: E402

from tests.frontend.browser import (  # noqa: E402
    CHROMIUM,
    CHROMIUM_ARGS,
    start_server,
    upload_example,
    wait_run,
)
from tests.frontend.page_load import Load, measure_loads  # noqa: E402
from tests.frontend.test_compare_versions_view import start_run  # noqa: E402

FIELDS = ("dcl_ms", "content_ms", "plot_ms")


def summarise(loads: list[Load]) -> list[dict]:
    """Median and worst of each timing per (view, cold|warm), in the order views were met."""
    groups: dict[tuple[str, str], list[Load]] = {}
    for x in loads:
        groups.setdefault((x.view, x.attempt), []).append(x)
    rows = []
    for (view, attempt), xs in groups.items():
        row: dict = {"view": view, "attempt": attempt, "loads": len(xs)}
        for f in FIELDS:
            values = [getattr(x, f) for x in xs]
            row[f] = {"median": round(statistics.median(values)), "max": round(max(values))}
        row["kib"] = round(statistics.median(x.bytes for x in xs) / 1024)
        rows.append(row)
    return rows


def format_rows(rows: list[dict]) -> str:
    titles = "  ".join(f"{t:>16}" for t in ("DOMContentLoaded", "view content", "first plot"))
    head = f"{'view':9} {'load':5} {'n':>3}  {titles}  {'KiB':>6}"
    lines = [head, "-" * len(head)]
    for r in rows:
        cells = "  ".join(f"{r[f]['median']:>8} ({r[f]['max']:>5})" for f in FIELDS)
        lines.append(f"{r['view']:9} {r['attempt']:5} {r['loads']:>3}  {cells}  {r['kib']:>6}")
    lines.append("milliseconds from the start of the navigation: median (worst)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=5, help="cold loads per view (default 5)")
    parser.add_argument("--warm", type=int, default=2, help="reloads after each cold load")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.warm < 1:
        parser.error("--rounds and --warm must be at least 1")

    with tempfile.TemporaryDirectory(prefix="mapwise-bench-dashboard-") as tmp:
        server = start_server(Path(tmp))
        try:
            with server.api() as api:
                dataset = upload_example(api, f"bench-{uuid.uuid4().hex[:8]}")
                run = wait_run(api, start_run(api, dataset["id"], "skf")["id"])
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
                loads: list[Load] = []
                for _ in range(args.rounds):
                    loads += measure_loads(browser, server.url, run, warm=args.warm)
                browser.close()
        finally:
            server.stop()
    rows = summarise(loads)
    print(json.dumps(rows, indent=2) if args.json else format_rows(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
