"""Suite-wide collection rules: every test under ``tests/frontend/`` drives Chromium and carries
the ``browser`` marker, so the fast lane (``scripts/test.sh --fast``) can leave it out.

The other markers (``slow``, ``postgres``, ``dask``, ``soak``, ``serial``) sit on the tests
themselves or, for ``postgres``, on the PostgreSQL parameter of the ``backend`` fixture
(tests/app/conftest.py). docs/contributing.md lists the lanes.

``--fail-on-skip`` (what ``scripts/test.sh`` gives the whole suite) fails the run if any test
was skipped: a missing Chromium or PostgreSQL must not pass CI as a green, smaller suite.
Under pytest-xdist the workers' reports reach the controller's hooks, so the controller
decides; a worker's own verdict would not reach the run's exit status.

The parallel phase of the whole suite (``pytest -n N --dist loadfile``, scripts/test.sh) gets
its own scheduler, :func:`pytest_xdist_make_scheduler`: a test file is one unit of work, so
its module-scoped servers and databases start once, and the units start longest first
(``LONGEST``), so that no long file starts last and keeps one worker busy alone at the end.
The files in ``EACH_TEST_ALONE`` start a server per test and share nothing per module, so
each of their tests is a unit of its own and they run side by side; in the
``EACH_BACKEND_ALONE`` files the tests of one backend share a server or app, so each
backend's tests are a unit.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest

# One BLAS thread per process, set before anything imports numpy: the suite runs several
# workers (and servers) on 2 cores, where OpenBLAS's threads spin on the many small matrices
# (35×35 expm, dense observer solves) and cost ~8× the CPU of the work itself.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# Datasets' samples go to an artifact store (MAPWISE_STORE_URL, default ./mapwise-data/ in
# the working directory): every app, worker and migration of this process, and the servers it
# starts, use a temporary one instead (tests/support/server.py gives each database its own).
if "MAPWISE_STORE_URL" not in os.environ:
    os.environ["MAPWISE_STORE_URL"] = tempfile.mkdtemp(prefix="mapwise-test-store-")
    atexit.register(shutil.rmtree, os.environ["MAPWISE_STORE_URL"], ignore_errors=True)

FRONTEND = Path(__file__).resolve().parent / "frontend"
_skipped: list[str] = []

# Seconds each file's tests took in the parallel phase (-n 3, the junit XML's test times, on
# 2026-12-03 with the machine shared by other jobs, so several times a quiet run's; see
# docs/contributing.md). Only their order matters: a file missing here starts after these.
# The files split for issue 14 have twice their longest unit's time measured alone at load
# 8-20 (2026-12-03, docs/contributing.md), to compare with the suite-measured ones.
LONGEST: dict[str, float] = {
    "tests/estimation/test_ekf.py": 590,
    "tests/app/runs/test_kill_storm.py": 500,
    "tests/app/runs/test_isolation.py": 480,
    "tests/app/runs/test_every_estimator.py": 480,
    "tests/app/runs/test_runs.py": 440,
    "tests/estimation/test_registry.py": 430,
    "tests/app/api/test_openapi_fuzz.py": 420,
    "tests/estimation/test_airpath_plant.py": 290,
    "tests/app/services/test_sweeps.py": 230,
    "tests/app/runs/test_attempts.py": 220,  # per backend
    "tests/app/api/test_api_contract.py": 220,
    "tests/frontend/test_every_estimator.py": 210,  # the NOx-map estimators
    "tests/frontend/test_views.py": 210,
    "tests/estimation/test_torque_estimators.py": 200,  # 1000 before one BLAS thread (above)
    "tests/app/runs/test_dask.py": 190,
    "tests/frontend/test_every_estimator_torque.py": 180,
    "tests/frontend/test_run_view.py": 180,
    "tests/estimation/test_torque_plant.py": 170,
    "tests/app/cli/test_reproduce.py": 170,
    "tests/app/api/test_auth.py": 170,
    "tests/estimation/test_filter_state.py": 170,
    "tests/app/runs/test_server_lifecycle.py": 160,  # per test
    "tests/app/db/test_migrations.py": 160,
    "tests/app/runs/test_live_server.py": 150,  # per backend
    "tests/frontend/test_sweeps_batches.py": 150,
    "tests/frontend/test_contrast.py": 150,
    "tests/estimation/test_lpv.py": 140,  # 520 before one BLAS thread: its CPU fell 4×
    "tests/app/runs/test_attempts_on_servers.py": 110,  # per test
    "tests/frontend/test_every_estimator_others.py": 100,
    # 2026-12-04 fresh clone, nothing else running: six held-out EKF tunings of 33-45 s
    "tests/estimation/test_tuning.py": 290,  # per test
}
# Each test starts its own server and the module keeps no fixture or cache: the kill storm
# (two tests of 50 kills, about half the file's time each), the isolation tests, and the
# servers killed, stopped and restarted (split out of test_live_server.py and
# test_attempts.py, whose shared-server tests stay one unit each).
EACH_TEST_ALONE = frozenset(
    {
        "tests/estimation/test_tuning.py",  # CPU-bound tunings, a module fixture of 60 s data
        "tests/app/runs/test_kill_storm.py",
        "tests/app/runs/test_isolation.py",
        "tests/app/runs/test_server_lifecycle.py",
        "tests/app/runs/test_attempts_on_servers.py",
    }
)
# Each backend's tests share their module's server or app (a fixture per backend), nothing
# across backends: a unit per backend, so SQLite's and PostgreSQL's halves run side by side.
EACH_BACKEND_ALONE = frozenset(
    {
        "tests/app/runs/test_live_server.py",
        "tests/app/runs/test_attempts.py",
        "tests/app/api/test_openapi_fuzz.py",
    }
)
BACKEND_IDS = ("sqlite", "postgresql")  # the ``backend`` fixture's ids (tests/app/conftest.py)


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
    if hasattr(config, "workerinput"):  # an xdist worker: its collection order is the queue's
        items.sort(key=lambda item: -LONGEST.get(_file_of(item.nodeid), 0.0))


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def _backend_of(nodeid: str) -> str:
    """The ``backend`` id among the test's parameter ids (``test_x[sqlite]``), else ``""``."""
    ids = nodeid.rsplit("[", 1)[1].rstrip("]").split("-") if nodeid.endswith("]") else []
    return next((i for i in ids if i in BACKEND_IDS), "")


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``--dist loadfile``, with the units in collection order (longest first, above) instead
    of xdist's "most tests first", a unit per test in the ``EACH_TEST_ALONE`` files and a
    unit per backend in the ``EACH_BACKEND_ALONE`` files."""
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class LongestFirst(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = _file_of(nodeid)
            if path in EACH_TEST_ALONE:
                return nodeid
            if path in EACH_BACKEND_ALONE:
                return f"{path}[{_backend_of(nodeid)}]"
            return path

    config.option.loadscopereorder = False
    return LongestFirst(config, log)


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if report.skipped and not hasattr(report, "wasxfail"):
        _skipped.append(report.nodeid)


def pytest_collectreport(report: pytest.CollectReport) -> None:
    if report.skipped:  # a module skipped as a whole (pytest.skip(allow_module_level=True))
        _skipped.append(report.nodeid)


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if hasattr(session.config, "workerinput"):  # an xdist worker: the controller decides
        return
    if session.config.getoption("--fail-on-skip") and _skipped and exitstatus == 0:
        print(f"\n--fail-on-skip: {len(_skipped)} skipped; the whole suite runs every test:")
        print("\n".join(f"  {nodeid}" for nodeid in _skipped))
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
