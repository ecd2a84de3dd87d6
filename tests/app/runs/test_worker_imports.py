"""What a run worker imports: the numerics, the database and the store, never the web layer
(docs/reliability.md#api-memory). Every spawned worker pays for what it imports, and a worker
is spawned again after each crash, kill or retirement."""

from __future__ import annotations

import json
import subprocess
import sys

WEB = ("fastapi", "starlette", "uvicorn", "httptools", "multipart", "python_multipart")


def test_the_run_worker_imports_no_web_framework() -> None:
    probe = (
        "import json, sys\n"
        "from app.runs.pool import worker_main, warm_up\n"
        "from app.runs.worker import execute_run\n"
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
