#!/usr/bin/env bash
# Lint and test mapwise (docs/contributing.md lists the lanes and their times).
#
#   scripts/test.sh            the whole suite, as CI runs it (.ci/run): every test, none skipped
#   scripts/test.sh --fast     ruff and every test that needs no PostgreSQL, Chromium, Dask,
#                              killed processes or a soak (< 3 min on 2 cores)
#
# Both lanes also check formatting (ruff, prettier) and build the docs (mkdocs --strict).
# Extra arguments go to pytest (scripts/test.sh --fast -k skf; scripts/test.sh tests/app/db);
# a marker expression among them (-m EXPR) narrows the lane's own.
#
# The whole suite runs in two phases: first every test not marked `serial`, spread over
# $MAPWISE_TEST_JOBS pytest-xdist workers (default 3; a test file stays on one worker, so its
# module-scoped servers and databases start once), then the `serial` tests one at a time (they
# bound latency, loop lag or frame rates, or restart the shared PostgreSQL). The phases'
# marker expressions are complements, so every collected test runs in exactly one of them.
#
# The whole suite first makes sure of Chromium and a running PostgreSQL (system-deps.sh, which
# installs only what is missing). Both lanes install mapwise with its test dependencies into
# ./.venv, again only when pyproject.toml changed since the last install (a stamp in .venv).
set -euo pipefail
cd "$(dirname "$0")/.."
# One BLAS thread per process (tests/conftest.py says why); the servers inherit it.
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"

FAST_LANE="not slow and not postgres and not browser and not dask and not soak"
fast=0
if [ "${1:-}" = "--fast" ]; then
    fast=1
    shift
fi
marks=""  # the caller's -m, combined with each lane's or phase's expression below
args=()
while [ "$#" -gt 0 ]; do
    case "$1" in
        -m) marks="${2:?-m needs a marker expression}"; shift 2 ;;
        -m*) marks="${1#-m}"; shift ;;
        *) args+=("$1"); shift ;;
    esac
done

# Runs pytest on the marker expression $1 (and the caller's -m) with the remaining arguments.
pytest_on() {
    local expression="$1"
    shift
    if [ -n "$marks" ]; then
        expression="($marks) and ($expression)"
    fi
    .venv/bin/pytest -m "$expression" "$@" ${args[@]+"${args[@]}"}
}

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
    # The same two phases as the whole suite, on two workers (MAPWISE_FAST_JOBS).
    parallel=0
    pytest_on "($FAST_LANE) and not serial" -n "${MAPWISE_FAST_JOBS:-2}" --dist loadfile ||
        parallel=$?
    serial=0
    pytest_on "($FAST_LANE) and serial" || serial=$?
    if [ "$parallel" -eq 5 ] && [ "$serial" -eq 5 ]; then  # only tests outside the lane
        echo "test.sh --fast: no fast-lane test matches; run them with scripts/test.sh" >&2
        exit 0
    fi
    for status in "$parallel" "$serial"; do
        if [ "$status" -ne 0 ] && [ "$status" -ne 5 ]; then
            exit "$status"
        fi
    done
    exit 0
fi

# The whole suite: a skipped test fails the run (tests/conftest.py). pytest's exit code 5
# (nothing collected) is fine for one phase, since arguments may pick no serial test, but
# an error if neither phase collected anything.
parallel=0
pytest_on "not serial" --fail-on-skip -n "${MAPWISE_TEST_JOBS:-3}" --dist loadfile || parallel=$?
serial=0
pytest_on "serial" --fail-on-skip || serial=$?
if [ "$parallel" -eq 5 ] && [ "$serial" -eq 5 ]; then
    exit 5
fi
for status in "$parallel" "$serial"; do
    if [ "$status" -ne 0 ] && [ "$status" -ne 5 ]; then
        exit "$status"
    fi
done
exit 0
