"""Browser tests of the dashboard: Debian's Chromium driven by Playwright (sync API) against a
real ``mapwise serve`` on a temporary SQLite database.

Every test module gets its own server on a fresh database (no test sees another module's
runs, datasets or base maps); every test gets a fresh browser context (cold cache, empty
storage) and fails if the page logged a console error or threw. Screenshots go to
``tests/artifacts/`` (git-ignored).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field

import httpx
import pytest
from playwright.sync_api import (
    Browser,
    ConsoleMessage,
    Page,
    expect,
    sync_playwright,
)

from tests.frontend.browser import CHROMIUM, CHROMIUM_ARGS, VIEWPORT, Server, start_server

# Playwright's assertions wait 5 s by default; the suite shares two cores with servers and
# other browsers, and a cold view can take longer than that there. Waiting longer changes
# nothing when the page is right, and a wrong page still fails (after 20 s).
expect.set_options(timeout=20_000)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    srv = start_server(tmp_path_factory.mktemp("mapwise-serve"))
    yield srv
    srv.stop()


# One Chromium per module, not per session: Playwright's sync API keeps an asyncio loop
# running in this thread while it is open, so under pytest-xdist a non-browser test that
# calls asyncio.run() afterwards on the same worker would fail.
@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    # A missing browser fails every browser test with the fix, never skips it (CI runs them all).
    if not CHROMIUM.exists():  # pragma: no cover - depends on the machine
        pytest.fail(
            f"Chromium is not installed at {CHROMIUM}: run scripts/system-deps.sh "
            "(apt-get install -y chromium)",
            pytrace=False,
        )
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield b
        b.close()


@dataclass
class Console:
    """Console errors and uncaught exceptions of one page.

    A test that provokes an API error on purpose allows the browser's own network log line
    for it (``console.allow(r"status of 422")``); nothing else is excused.
    """

    errors: list[str] = field(default_factory=list)
    allowed: list[re.Pattern[str]] = field(default_factory=list)

    def allow(self, pattern: str) -> None:
        self.allowed.append(re.compile(pattern))

    def on_console(self, msg: ConsoleMessage) -> None:
        if msg.type == "error":
            self.errors.append(f"console.error: {msg.text} ({msg.location.get('url', '')})")

    def on_page_error(self, exc: Exception) -> None:
        self.errors.append(f"uncaught: {exc}")

    def unexpected(self) -> list[str]:
        return [e for e in self.errors if not any(p.search(e) for p in self.allowed)]


@pytest.fixture
def console() -> Console:
    return Console()


@pytest.fixture
def page(browser: Browser, server: Server, console: Console) -> Iterator[Page]:
    context = browser.new_context(
        base_url=server.url, viewport=VIEWPORT, accept_downloads=True, color_scheme="light"
    )
    context.set_default_timeout(20_000)
    pg = context.new_page()
    pg.on("console", console.on_console)
    pg.on("pageerror", console.on_page_error)
    yield pg
    context.close()
    assert console.unexpected() == [], "\n".join(console.unexpected())


@pytest.fixture
def api(server: Server) -> Iterator[httpx.Client]:
    with server.api() as client:
        yield client
