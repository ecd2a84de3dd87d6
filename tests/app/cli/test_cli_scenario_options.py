"""``--noise-scale`` and ``--transient-24s`` of ``mapwise simulate`` and ``mapwise run``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.io.csv_files import read_csv
from estimation.plants.torque import TRANSIENT_24S_RPM, TRANSIENT_24S_S


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_run_noise_scale_zero_is_a_noise_free_log(capsys: pytest.CaptureFixture[str]) -> None:
    base = ["run", "--scenario", "skf-sim3", "--estimator", "kf", "--json"]
    code, out, err = run([*base, "--noise-scale", "0"], capsys)
    assert code == 0, err
    quiet = json.loads(out)
    code, out, err = run(base, capsys)
    assert code == 0, err
    plain = json.loads(out)
    assert quiet["noise_scale"] == 0.0
    assert plain["noise_scale"] == 1.0
    # the filter's σv stays as configured; without noise its map error is smaller
    assert quiet["config"]["sigma_v"] == plain["config"]["sigma_v"]
    assert quiet["metrics"]["rmse"] < plain["metrics"]["rmse"]
    code, out, _ = run([*base[:-1], "--noise-scale", "2"], capsys)
    assert code == 0
    assert "noise × 2" in out


def test_run_refuses_a_bad_noise_scale(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(
        ["run", "--scenario", "skf-sim3", "--estimator", "kf", "--noise-scale", "-1"], capsys
    )
    assert code != 0
    assert "noise_scale" in err


def test_simulate_transient_24s(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv, truth = tmp_path / "si.csv", tmp_path / "si.json"
    args = ["simulate", "--scenario", "torque-si", "--duration", "24.5", "--out", str(csv)]
    code, _, err = run([*args, "--truth", str(truth), "--transient-24s"], capsys)
    assert code == 0, err
    log = read_csv(csv).signals
    t, ref = log.time, log["speed_setpoint_rpm"]
    assert np.all(ref[t >= TRANSIENT_24S_S + 1e-6] == TRANSIENT_24S_RPM)
    assert np.all(ref[(t > 14.1) & (t < TRANSIENT_24S_S - 1e-6)] != TRANSIENT_24S_RPM)
    assert json.loads(truth.read_text())["metadata"]["transient_24s"] is True
    code, _, err = run(
        ["simulate", "--scenario", "torque-rig", "--out", str(csv), "--transient-24s"], capsys
    )
    assert code != 0
    assert "transient_24s" in err
