"""Where the top-level ``frontend/`` and ``migrations/`` directories are.

In a checkout (and an editable install) they sit beside ``app/``; a wheel carries copies inside
the package (``app/_bundled/``, see ``[tool.hatch.build.targets.wheel.force-include]`` in
``pyproject.toml``) so that ``pip install .`` (the Docker image) serves the same files.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def resource_dir(name: str) -> Path:
    """The checkout's ``name/`` directory if present, else the wheel's bundled copy."""
    for candidate in (_PACKAGE.parent / name, _PACKAGE / "_bundled" / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"mapwise is installed without its {name}/ directory")
