"""Shared fixtures of the calibration tests: the ASAM demo A2L from the pya2ldb wheel.

``demo_a2l`` is the wheel's file as shipped (stripped: no RECORD_LAYOUTs, see
:mod:`tests.app.calibration.demo_a2l`); ``full_demo_a2l`` is the completed copy that values
decode with. Each is parsed once per test session (per xdist worker) into a session cache.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from app.calibration.a2l import A2lFile, open_a2l
from tests.app.calibration.demo_a2l import DEMO_A2L, full_demo_text


@pytest.fixture(scope="session")
def demo_a2l_path() -> Path:
    return DEMO_A2L


@pytest.fixture(scope="session")
def demo_a2l_bytes() -> bytes:
    return DEMO_A2L.read_bytes()


@pytest.fixture(scope="session")
def full_demo_a2l_bytes() -> bytes:
    return full_demo_text().encode("latin-1")


@pytest.fixture(scope="session")
def shared_a2l_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One A2L cache for the session's parsed demos."""
    return tmp_path_factory.mktemp("a2l-cache")


@pytest.fixture(scope="session")
def demo_a2l(demo_a2l_bytes: bytes, shared_a2l_cache: Path) -> A2lFile:
    return open_a2l(demo_a2l_bytes, cache_dir=shared_a2l_cache)


@pytest.fixture(scope="session")
def full_demo_a2l(full_demo_a2l_bytes: bytes, shared_a2l_cache: Path) -> A2lFile:
    return open_a2l(full_demo_a2l_bytes, cache_dir=shared_a2l_cache)


@pytest.fixture
def a2l_cache_dir(tmp_path: Path) -> Path:
    """An empty cache directory of the test's own."""
    path = tmp_path / "a2l-cache"
    path.mkdir()
    return path
