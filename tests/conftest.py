"""Suite-wide collection rules: every test under ``tests/frontend/`` drives Chromium and carries
the ``browser`` marker, so the fast lane (``scripts/test.sh --fast``) can leave it out.

The other markers (``slow``, ``postgres``, ``dask``, ``soak``) sit on the tests themselves
or, for ``postgres``, on the PostgreSQL parameter of the ``backend`` fixture
(tests/app/conftest.py). docs/contributing.md lists the lanes.

``--fail-on-skip`` (what ``scripts/test.sh`` gives the whole suite) fails the run if any test
was skipped: a missing Chromium or PostgreSQL must not pass CI as a green, smaller suite.
"""

from __future__ import annotations

from pathlib import Path

import pytest

FRONTEND = Path(__file__).resolve().parent / "frontend"
_skipped: list[str] = []


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--fail-on-skip",
        action="store_true",
        help="fail the run if a test was skipped (the whole suite runs every test)",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.is_relative_to(FRONTEND):
            item.add_marker(pytest.mark.browser)


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if report.skipped and not hasattr(report, "wasxfail"):
        _skipped.append(report.nodeid)


def pytest_collectreport(report: pytest.CollectReport) -> None:
    if report.skipped:  # a module skipped as a whole (pytest.skip(allow_module_level=True))
        _skipped.append(report.nodeid)


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if session.config.getoption("--fail-on-skip") and _skipped and exitstatus == 0:
        print(f"\n--fail-on-skip: {len(_skipped)} skipped; the whole suite runs every test:")
        print("\n".join(f"  {nodeid}" for nodeid in _skipped))
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
