#!/usr/bin/env bash
# Install mapwise into ./.venv and start the dashboard on the embedded default: SQLite in
# ./mapwise.db (WAL). An empty database gets the schema, the demo NOx drive log and a finished
# SKF run learning the SKF paper's 12×18 NOx map (SKF (34)). Open http://127.0.0.1:8000.
# Extra arguments go to `mapwise serve` (e.g. --port 8080, --database-url postgresql+psycopg://…).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip "setuptools>=78.1.1"
.venv/bin/python -m pip install --quiet -e .
exec .venv/bin/mapwise serve "$@"
