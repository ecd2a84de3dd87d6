"""The dashboard's pure grid maths (``frontend/js/grid-math.js``) under Node's test runner:
cell edges, breakpoint look-up, interpolation against a slow reference, slices and colour
ranges. No browser or server; the assertions live in ``js/grid-math.test.js``."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

TESTS = Path(__file__).parent / "js" / "grid-math.test.js"
NODE = shutil.which("node")


def test_grid_math_under_node() -> None:
    assert NODE is not None, (
        "Node.js is not installed (apt-get install -y nodejs): these tests run under it"
    )
    done = subprocess.run(
        [NODE, "--test", str(TESTS)],
        cwd=TESTS.parents[3],  # the repository: its package.json makes the modules ES modules
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "# fail 0" in done.stdout, done.stdout
    assert "# pass 0" not in done.stdout, done.stdout  # the file ran its tests
