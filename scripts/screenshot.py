"""Make ``docs/screenshot.png``: the Run view at 1400×900 while an SKF run adapts the NOx map.

Uses the browser tests' setup (Debian's Chromium through Playwright, a real ``mapwise serve``
on a temporary SQLite database): uploads the bundled example log, starts the SKF with the
paper's settings at a watchable pace and captures the page part-way through the run, with
the operating-point trail and the active cell on the map.

    .venv/bin/python scripts/screenshot.py [--out docs/screenshot.png] [--theme dark|light]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scripts.page_shot import capture, chromium_missing, open_page, parse_args  # noqa: E402
from tests.frontend.browser import start_server, upload_example  # noqa: E402

# The 12×18 NOx grid and SKF settings of the SKF paper's example (SKF (34)).
SPEED_RPM = [750, 780, 1000, 1250, 1500, 1750, 2000, 2500, 3000, 3500, 4000, 4500]
FUEL_MG = [0, 5, 10, 15, 20, 25, 30, 34, 38, 42, 46, 50, 55, 60, 65, 70, 75, 80]
RUN = {
    "estimator": "skf",
    "name": "SKF learns the NOx map",
    "signals": {"y": "nox_ppm"},
    "table": {
        "axes": [
            {"name": "speed_rpm", "breakpoints": SPEED_RPM},
            {"name": "fuel_mg_per_stroke", "breakpoints": FUEL_MG},
        ]
    },
    "config": {
        "sigma_w": 15.0,
        "sigma_v": 25.0,
        "p0": 10000.0,
        "sensor": {"lag": 0.96, "delay_s": 0.75, "sigma_f": 50.0},
        "pace": 6,
    },
}
CAPTURE_AT = 0.62  # fraction of the log processed when the picture is taken


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv, __doc__, ROOT / "docs" / "screenshot.png")
    if chromium_missing("screenshot"):
        return 2

    with tempfile.TemporaryDirectory(prefix="mapwise-shot-") as tmp:
        server = start_server(Path(tmp))
        try:
            with server.api() as api:
                dataset = upload_example(api, "NOx drive, 150 s at 50 Hz")
                r = api.post("/api/runs", json={"dataset_id": dataset["id"], **RUN})
                r.raise_for_status()
                run_id = r.json()["id"]
                with open_page(f"{server.url}/runs/{run_id}", args.theme) as page:
                    page.locator('[data-plot="map"] .main-svg').first.wait_for()
                    deadline = time.monotonic() + 120
                    while api.get(f"/api/runs/{run_id}").json()["progress"] < CAPTURE_AT:
                        if time.monotonic() > deadline:
                            raise RuntimeError("the run did not progress")
                        time.sleep(0.2)
                    capture(page, args.out)
        finally:
            server.stop()
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
