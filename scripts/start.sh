#!/usr/bin/env bash
# Install mapwise into ./.venv and run the demo: learn the 12×18 NOx map of the SKF paper's
# case study (SKF (34)) from the shipped 150 s drive log with the simplified Kalman filter,
# sensor lag and delay included, and print it.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e .
exec .venv/bin/mapwise adapt app/data/example_nox.csv --estimator skf \
    --axis speed_rpm=750,780,1000,1250,1500,1750,2000,2500,3000,3500,4000,4500 \
    --axis fuel_mg_per_stroke=0,5,10,15,20,25,30,34,38,42,46,50,55,60,65,70,75,80 \
    --y nox_ppm --sigma-w 15 --sigma-v 25 --p0 10000 \
    --lag 0.96 --delay-s 0.75 --sigma-f 50 --time time "$@"
