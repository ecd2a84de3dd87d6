"""A wheel (``pip install .``, the Docker image) serves the same dashboard and migrations as a
checkout: ``frontend/`` and ``migrations/`` travel inside the package (app.resources)."""

from __future__ import annotations

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
