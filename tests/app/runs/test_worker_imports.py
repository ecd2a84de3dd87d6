"""What a run worker imports: the numerics, the database and the store, never the web layer
(docs/reliability.md#api-memory). The workers' fork server imports it all once
(``app.runs.prewarm``), and every worker, including each replacement after a crash, kill or
retirement, is forked from it with what it holds."""

from __future__ import annotations

import json
import subprocess
import sys

WEB = ("fastapi", "starlette", "uvicorn", "httptools", "multipart", "python_multipart")


def test_the_run_worker_imports_no_web_framework() -> None:
    probe = (
        "import json, sys\n"
        "import app.cli.main\n"  # `mapwise serve`'s main module, which the fork server preloads
        "import app.runs.prewarm\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True
    )
    loaded = json.loads(done.stdout)
    web = [m for m in loaded if m.split(".")[0] in WEB]
    assert web == [], web
    assert "app.runs.worker" in loaded  # the probe did import the worker
    assert "sqlalchemy.orm" in loaded
