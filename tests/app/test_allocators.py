"""The API process's allocators (app/allocators.py), set in a fresh interpreter: this one's
pyarrow pool stays as the tests found it."""

from __future__ import annotations

import subprocess
import sys

CHECK = """
import ctypes
from app.allocators import use_lean_allocators
import pyarrow as pa
before = pa.default_memory_pool().backend_name
use_lean_allocators()
print(before, pa.default_memory_pool().backend_name)
"""


def test_the_api_allocates_with_the_system_pool() -> None:
    out = subprocess.run(
        [sys.executable, "-c", CHECK], capture_output=True, text=True, check=True, timeout=60
    ).stdout.split()
    assert out[1] == "system", out
    assert out[0] != "system", "the default pool was already the system's: nothing is tested"
