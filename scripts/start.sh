#!/usr/bin/env bash
# Install mapwise into ./.venv and start the dashboard on the embedded default: SQLite in
# ./mapwise.db (WAL). An empty database gets the schema, the demo NOx drive log and a finished
# SKF run learning the SKF paper's 12×18 NOx map (SKF (34)); the URL of that run is printed.
# The install is skipped when ./.venv is current for this pyproject.toml (a stamp in .venv,
# shared with scripts/test.sh), so a second start only starts the server.
# Extra arguments go to `mapwise serve` (e.g. --port 8080, --database-url postgresql+psycopg://…).
set -euo pipefail
cd "$(dirname "$0")/.."

hash="$(sha256sum pyproject.toml | cut -c1-16)"
if [ -x .venv/bin/mapwise ] && [ -e ".venv/.mapwise-install-$hash" -o -e ".venv/.mapwise-serve-$hash" ]; then
    echo "mapwise: ./.venv is current; starting" >&2
else
    echo "mapwise: [1/3] creating ./.venv" >&2
    python3 -m venv .venv
    echo "mapwise: [2/3] updating pip" >&2
    .venv/bin/python -m pip install --quiet --upgrade pip "setuptools>=78.1.1"
    echo "mapwise: [3/3] installing mapwise and its dependencies (a few minutes the first time)" >&2
    .venv/bin/python -m pip install --progress-bar off -e . 2>&1 |
        grep --line-buffered -E '^(Collecting|Successfully installed|ERROR)' |
        sed -u 's/^/  /' >&2 || true
    .venv/bin/python -c "import app, estimation" # fails loudly if the install did not work
    rm -f .venv/.mapwise-serve-*
    touch ".venv/.mapwise-serve-$hash"
fi
exec .venv/bin/mapwise serve "$@"
