#!/usr/bin/env bash
# System services and packages the full test suite needs on a Debian machine, each installed
# or started only when missing (a machine that has them makes no apt call at all):
# - Chromium for the browser tests (Debian's package; Playwright never downloads a browser);
# - Node.js and npm for prettier and the frontend's unit tests;
# - a running local PostgreSQL at 127.0.0.1:5432 with trust auth and a database `test`, for
#   the PostgreSQL half of the service tests.
set -euo pipefail
as_root() { if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi; }

missing=()
command -v chromium >/dev/null 2>&1 || missing+=(chromium)
command -v node >/dev/null 2>&1 || missing+=(nodejs)
command -v npm >/dev/null 2>&1 || missing+=(npm)
command -v pg_ctlcluster >/dev/null 2>&1 || missing+=(postgresql)
if [ "${#missing[@]}" -gt 0 ]; then
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
fi

if ! pg_isready -q -h 127.0.0.1 -p 5432; then
    version="$(ls /etc/postgresql | sort -V | tail -n1)"
    hba="/etc/postgresql/$version/main/pg_hba.conf"
    if ! as_root grep -q '^host all all 127.0.0.1/32 trust' "$hba"; then
        # Tests connect as postgres without a password, over TCP on loopback only.
        as_root sed -i '/^[^#]/d' "$hba"
        printf '%s\n' 'local all all trust' 'host all all 127.0.0.1/32 trust' \
            'host all all ::1/128 trust' | as_root tee -a "$hba" >/dev/null
    fi
    as_root pg_ctlcluster --skip-systemctl-redirect "$version" main start
    for _ in $(seq 30); do pg_isready -q -h 127.0.0.1 -p 5432 && break; sleep 1; done
    pg_isready -h 127.0.0.1 -p 5432
fi

if ! psql -h 127.0.0.1 -U postgres -d test -Atc 'select 1' >/dev/null 2>&1; then
    psql -h 127.0.0.1 -U postgres -d postgres -qc 'CREATE DATABASE test'
fi
