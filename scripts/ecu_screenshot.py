"""Make ``docs/img/ecu-view.png``: the ECU view at 1400×900 with a demo MAP open.

Uses the browser tests' setup (Debian's Chromium through Playwright, a real ``mapwise serve``
on a temporary SQLite database) and the files of the ECU walk-through
(``tests/frontend/ecu_files.py``): uploads the ASAM demo A2L with a HEX image holding known
values of ``ASAM.C.MAP.STD_AXIS.STD_AXIS`` and captures that map's page — the searchable
list of characteristics beside the heatmap of its stored values in its unit.

    .venv/bin/python scripts/ecu_screenshot.py [--out docs/img/ecu-view.png] [--theme dark|light]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from urllib.parse import quote

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from playwright.sync_api import sync_playwright  # noqa: E402

from tests.frontend.browser import CHROMIUM, CHROMIUM_ARGS, VIEWPORT, start_server  # noqa: E402
from tests.frontend.ecu_files import MAP_NAME, write_files  # noqa: E402

#: Parsing the demo A2L takes seconds (pya2ldb), tens on a busy machine.
UPLOAD_TIMEOUT_S = 300.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "ecu-view.png")
    parser.add_argument("--theme", choices=["dark", "light"], default="dark")
    args = parser.parse_args(argv)
    if not CHROMIUM.exists():
        print(
            "ecu_screenshot: error: /usr/bin/chromium is missing (apt-get install chromium)",
            file=sys.stderr,
        )
        return 2

    with tempfile.TemporaryDirectory(prefix="mapwise-shot-") as tmp:
        a2l, image, _ = write_files(Path(tmp))
        server = start_server(Path(tmp))
        try:
            with server.api(timeout=UPLOAD_TIMEOUT_S) as api:
                with a2l.open("rb") as fa, image.open("rb") as fv:
                    r = api.post(
                        "/api/ecus",
                        files={"a2l": (a2l.name, fa), "values": (image.name, fv)},
                        data={"name": "ASAM demo ECU"},
                    )
                r.raise_for_status()
                ecu_id = r.json()["id"]
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
                page = browser.new_page(viewport=VIEWPORT, color_scheme=args.theme)
                page.goto(f"{server.url}/ecus/{ecu_id}?map={quote(MAP_NAME)}")
                page.locator('[data-plot="ecu-map"] .main-svg').first.wait_for()
                page.locator("[data-map-list] [data-map]").first.wait_for()
                page.mouse.move(5, 890)  # no hover labels in the picture
                page.wait_for_timeout(400)
                args.out.parent.mkdir(parents=True, exist_ok=True)
                page.screenshot(path=str(args.out))
                browser.close()
        finally:
            server.stop()
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
