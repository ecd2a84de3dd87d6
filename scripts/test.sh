#!/usr/bin/env bash
# Install what the suite needs (Chromium, a running PostgreSQL; see system-deps.sh) and mapwise
# with its test dependencies into ./.venv, then lint and run the whole suite.
# Extra arguments go to pytest (e.g. scripts/test.sh -k skf).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/system-deps.sh
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip "setuptools>=78.1.1"
.venv/bin/python -m pip install --quiet -e '.[test]'
.venv/bin/ruff check .
.venv/bin/ruff format --check .
.venv/bin/pytest "$@"
