"""A wheel (``pip install .``, the Docker image) serves the same dashboard and migrations as a
checkout: ``frontend/`` and ``migrations/`` travel inside the package (app.resources)."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_wheel_bundles_frontend_and_migrations(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(tmp_path), str(ROOT)],
        check=True,
    )  # fmt: skip
    (wheel,) = tmp_path.glob("mapwise-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for source in [*ROOT.glob("frontend/**/*.*"), *ROOT.glob("migrations/**/*.py")]:
        if "__pycache__" in source.parts:
            continue
        assert f"app/_bundled/{source.relative_to(ROOT).as_posix()}" in names, source
    assert "app/data/example_nox.csv" in names
    assert "estimation/cycles/data/whtc.txt" in names
    assert not any(n.startswith(("frontend/", "migrations/", "tests/")) for n in names)

    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target),
         str(wheel)],
        check=True,
    )  # fmt: skip
    probe = "from app.resources import resource_dir as r; print(r('frontend'), r('migrations'))"
    found = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=tmp_path, env={"PYTHONPATH": str(target)}, capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    assert found == [str(target / "app/_bundled/frontend"), str(target / "app/_bundled/migrations")]


def test_compose_topology_runs_commands_that_exist() -> None:
    """docker-compose.yml (no Docker engine here): the app, PostgreSQL, a migration step, a
    Dask scheduler and workers, every command one this installation has. The same topology
    runs without Docker in tests/app/service/test_dask.py."""
    import shutil

    import yaml

    from app.cli import build_parser
    from app.config import Settings

    compose = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
    services = compose["services"]
    assert set(services) == {"db", "migrate", "scheduler", "worker", "app"}
    for name in ("migrate", "scheduler", "worker", "app"):
        assert services[name]["build"] == "."
    assert build_parser().parse_args(services["migrate"]["command"][1:]).db_command == "upgrade"
    dockerfile = (ROOT / "Dockerfile").read_text()
    cmd = json.loads(dockerfile.split("CMD ", 1)[1].splitlines()[0])
    assert build_parser().parse_args(cmd[1:]).host == "0.0.0.0"
    for name in ("scheduler", "worker"):
        assert services[name]["command"][0] == "dask"
        assert shutil.which("dask", path=str(Path(sys.executable).parent))
    env = services["app"]["environment"]
    settings = Settings(**{k.removeprefix("MAPWISE_").lower(): v for k, v in env.items()})
    assert settings.executor == "dask"
    assert settings.dask_address == "tcp://scheduler:8786"
    assert services["worker"]["environment"] == env
