"""Make ``docs/img/ecu-view.png``: the ECU view at 1400×900 with a demo MAP open.

Uses the browser tests' setup (Debian's Chromium through Playwright, a real ``mapwise serve``
on a temporary SQLite database) and the files of the ECU walk-through
(``tests/frontend/ecu_files.py``): uploads the ASAM demo A2L with a HEX image holding known
values of ``ASAM.C.MAP.STD_AXIS.STD_AXIS`` and captures that map's page — the searchable
list of characteristics beside the heatmap of its stored values in its unit.

    .venv/bin/python scripts/ecu_screenshot.py [--out docs/img/ecu-view.png] [--theme dark|light]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from urllib.parse import quote

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scripts.page_shot import capture, chromium_missing, open_page, parse_args  # noqa: E402
from tests.frontend.browser import start_server  # noqa: E402
from tests.frontend.ecu_files import MAP_NAME, write_files  # noqa: E402

#: Parsing the demo A2L takes seconds (pya2ldb), tens on a busy machine.
UPLOAD_TIMEOUT_S = 300.0


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv, __doc__, ROOT / "docs" / "img" / "ecu-view.png")
    if chromium_missing("ecu_screenshot"):
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
            url = f"{server.url}/ecus/{ecu_id}?map={quote(MAP_NAME)}"
            with open_page(url, args.theme) as page:
                page.locator('[data-plot="ecu-map"] .main-svg').first.wait_for()
                page.locator("[data-map-list] [data-map]").first.wait_for()
                capture(page, args.out)
        finally:
            server.stop()
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
