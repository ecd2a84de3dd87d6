#!/usr/bin/env bash
# Lint and test mapwise (docs/contributing.md lists the lanes and their times).
#
#   scripts/test.sh            the whole suite, as CI runs it (.ci/run): every test, none skipped
#   scripts/test.sh --fast     ruff and every test that needs no PostgreSQL, Chromium, Dask,
#                              killed processes or a soak (< 3 min on 2 cores)
#
# Both lanes also check formatting (ruff, prettier) and build the docs (mkdocs --strict).
# Extra arguments go to pytest (scripts/test.sh --fast -k skf; scripts/test.sh tests/app/db).
# The whole suite first makes sure of Chromium and a running PostgreSQL (system-deps.sh, which
# installs only what is missing). Both lanes install mapwise with its test dependencies into
# ./.venv, again only when pyproject.toml changed since the last install (a stamp in .venv).
set -euo pipefail
cd "$(dirname "$0")/.."

FAST_LANE="not slow and not postgres and not browser and not dask and not soak"
fast=0
if [ "${1:-}" = "--fast" ]; then
    fast=1
    shift
fi

if [ "$fast" -eq 0 ]; then
    bash scripts/system-deps.sh
fi

stamp=".venv/.mapwise-install-$(sha256sum pyproject.toml | cut -c1-16)"
if [ ! -x .venv/bin/python ] || [ ! -e "$stamp" ]; then
    python3 -m venv .venv
    .venv/bin/python -m pip install --quiet --upgrade pip "setuptools>=78.1.1"
    .venv/bin/python -m pip install --quiet -e '.[test,docs]'
    rm -f .venv/.mapwise-install-*
    touch "$stamp"
fi

# Prettier from package-lock.json, installed into ./node_modules when the lock changed.
npm_stamp="node_modules/.mapwise-install-$(sha256sum package-lock.json | cut -c1-16)"
if [ ! -e "$npm_stamp" ]; then
    npm ci --no-audit --no-fund --loglevel=error
    touch "$npm_stamp"
fi

.venv/bin/ruff check .
.venv/bin/ruff format --check .
npm run --silent format:check
NO_MKDOCS_2_WARNING=1 .venv/bin/mkdocs build --strict --quiet -d "$(mktemp -d)"

if [ "$fast" -eq 1 ]; then
    status=0
    .venv/bin/pytest -m "$FAST_LANE" "$@" || status=$?
    if [ "$status" -eq 5 ]; then  # the arguments picked only tests outside the fast lane
        echo "test.sh --fast: no fast-lane test matches; run them with scripts/test.sh" >&2
        exit 0
    fi
    exit "$status"
fi
# The whole suite: a skipped test fails the run (tests/conftest.py), and pytest's exit code 5
# (nothing collected) is an error like any other non-zero status.
exec .venv/bin/pytest --fail-on-skip "$@"
