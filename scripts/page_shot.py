"""What the documentation screenshot scripts share (``scripts/screenshot.py``,
``scripts/ecu_screenshot.py``): their command line, the Chromium check, a page of the app in
Debian's Chromium through Playwright at the browser tests' viewport, and the capture itself.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from playwright.sync_api import Page, sync_playwright

from tests.frontend.browser import CHROMIUM, CHROMIUM_ARGS, VIEWPORT


def parse_args(argv: list[str] | None, doc: str, default_out: Path) -> argparse.Namespace:
    """``--out PNG`` (default ``default_out``) and ``--theme dark|light``; the description is
    the first paragraph of the script's docstring ``doc``."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=default_out)
    parser.add_argument("--theme", choices=["dark", "light"], default="dark")
    return parser.parse_args(argv)


def chromium_missing(prog: str) -> bool:
    """Whether Chromium is absent (then said on stderr, prefixed by the script name ``prog``)."""
    if CHROMIUM.exists():
        return False
    print(
        f"{prog}: error: /usr/bin/chromium is missing (apt-get install chromium)",
        file=sys.stderr,
    )
    return True


@contextmanager
def open_page(url: str, theme: str) -> Iterator[Page]:
    """A page showing ``url`` in the ``theme`` colour scheme; the browser closes on exit."""
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport=VIEWPORT, color_scheme=theme)
        page.goto(url)
        yield page
        browser.close()


def capture(page: Page, out: Path) -> None:
    """Write the page as a PNG to ``out`` with the pointer parked where no hover label shows."""
    page.mouse.move(5, 890)
    page.wait_for_timeout(400)
    out.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(out))
