"""The service's A2L cache (:mod:`app.services.a2l_cache`): a hit on disk does not wait for
another A2L's parse, a miss does (parses run one at a time), docs/calibration.md#rest-and-cli."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from app.calibration import a2l as a2l_module
from app.calibration.a2l import A2lFile
from app.services import a2l_cache
from app.services.a2l_cache import CacheLimits, forget, open_bytes
from tests.app.calibration.test_a2l import MINI_A2L

pytestmark = pytest.mark.slow  # two real parses by pya2ldb in a child process


def _open_in_thread(data: bytes, limits: CacheLimits, out: list[A2lFile]) -> threading.Thread:
    thread = threading.Thread(target=lambda: out.append(open_bytes(data, limits)), daemon=True)
    thread.start()
    return thread


def test_a_cached_a2l_reopens_while_another_parses(tmp_path: Path) -> None:
    """The test holds the parse lock as a parse of another A2L does: the cached A2L still
    opens from disk at once, while a new A2L waits for the lock, then parses."""
    limits = CacheLimits(tmp_path, max_files=100, max_bytes=10**9)
    cached = MINI_A2L.encode("utf-8")
    other = MINI_A2L.replace("Mini", "Other").encode("utf-8")
    first = open_bytes(cached, limits)
    assert not first.from_cache
    forget()  # the service's memory copies …
    a2l_module._MEMO.clear()  # … and the reader's: the next open reads the disk entry
    hit: list[A2lFile] = []
    miss: list[A2lFile] = []
    with a2l_cache._parse_lock:
        reopen = _open_in_thread(cached, limits, hit)
        reopen.join(timeout=20.0)
        assert not reopen.is_alive(), "a disk-cache hit waited for another A2L's parse"
        parse = _open_in_thread(other, limits, miss)
        parse.join(timeout=1.0)
        assert parse.is_alive()  # a miss waits for the lock
        assert not miss
    parse.join(timeout=120.0)
    assert hit[0].from_cache
    assert hit[0].characteristics == first.characteristics
    assert not miss[0].from_cache
    assert miss[0].sha256 != first.sha256
