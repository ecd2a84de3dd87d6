"""``mapwise tune``: noise settings from a CSV log without truth, through the real CLI."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from estimation.scenarios import get_scenario
from estimation.tuning import MAX_EVALUATIONS

NOX_AXES = [
    "--axis", "speed_rpm=750,780,1000,1250,1500,1750,2000,2500,3000,3500,4000,4500",
    "--axis", "fuel_mg_per_stroke=0,5,10,15,20,25,30,34,38,42,46,50,55,60,65,70,75,80",
]  # fmt: skip
SYNTH_AXES = ["--axis", "u=0,1,2,3"]


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def nox_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, float]:
    """600 s of the held-out seed 104 of ``nox-nedc`` as a CSV (inputs and the measured
    NOx only), the estimator-side sensor model drawn for it, and its true σv."""
    scenario = get_scenario("nox-nedc")
    data = scenario.build(seed=104, duration_s=600.0)
    s = data.signals
    rows = ["time [s],speed_rpm [rpm],fuel_mg_per_stroke [mg/stroke],nox_ppm [ppm]"]
    rows += [
        f"{t:.2f},{n:.3f},{m:.4f},{y:.4f}"
        for t, n, m, y in zip(
            s.time, s["speed_rpm"], s["fuel_mg_per_stroke"], s["nox_ppm"], strict=True
        )
    ]
    path = tmp_path_factory.mktemp("tune") / "nox.csv"
    path.write_text("\n".join(rows) + "\n")
    sensor = scenario.default_config("skf", data)["sensor"]
    sigma_v = float(np.std(s["nox_ppm"] - np.asarray(data.truth["nox_sensor_noise_free_ppm"])))
    return path, sensor, sigma_v


@pytest.fixture
def small_log(tmp_path: Path) -> Path:
    rng = np.random.default_rng(0)
    u = rng.uniform(0.0, 3.0, 1500)
    y = np.interp(u, [0, 1, 2, 3], [10.0, 30.0, 20.0, 40.0]) + rng.normal(0.0, 0.5, u.size)
    rows = ["u [rpm],y [ppm]"] + [f"{a:.5f},{b:.5f}" for a, b in zip(u, y, strict=True)]
    path = tmp_path / "small.csv"
    path.write_text("\n".join(rows) + "\n")
    return path


def test_tune_a_nox_log_lands_within_two_of_sigma_v(
    nox_log: tuple[Path, dict, float], capsys: pytest.CaptureFixture[str]
) -> None:
    path, sensor, sigma_v = nox_log
    code, out, err = run(
        [
            "tune", str(path), "--estimator", "skf", *NOX_AXES, "--y", "nox_ppm",
            "--time", "time", "--p0", "10000", "--lag", str(sensor["lag"]),
            "--delay-s", str(sensor["delay_s"]), "--max-evals", "80",
        ],
        capsys,
    )  # fmt: skip
    assert (code, err) == (0, "")
    doc = json.loads(out)
    assert set(doc["parameters"]) == {"sigma_w", "sigma_v", "sigma_f"}
    assert sigma_v / 2 <= doc["parameters"]["sigma_v"] <= 2 * sigma_v
    assert 0 < doc["evaluations"] <= doc["max_evaluations"] == 80
    assert doc["unit"] == "ppm"
    assert math.isfinite(doc["log_likelihood"])
    innovation = doc["innovation"]
    assert innovation["log_likelihood"] == doc["log_likelihood"]
    lo, hi = innovation["mean_nis_band"]
    assert lo < 1.0 < hi
    assert 0.8 < innovation["mean_nis"] < 1.25
    holdout = doc["holdout"]
    assert holdout["fit_samples"] + holdout["holdout_samples"] == doc["samples"] == 30001
    assert holdout["adapted"]["rmse"] < holdout["base"]["rmse"]
    assert set(doc["timing"]) == {"load_s", "tune_s"}


def test_starts_and_budget_are_honoured(
    small_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run(
        [
            "tune", str(small_log), "--estimator", "kf", *SYNTH_AXES, "--y", "y", "--p0", "1000",
            "--sigma-v", "3", "--sigma-w", "0.1", "--max-evals", "7",
        ],
        capsys,
    )  # fmt: skip
    doc = json.loads(out)
    assert code == 0
    assert doc["start"] == {"sigma_w": 0.1, "sigma_v": 3.0}
    assert doc["evaluations"] == 7


BAD_ARGUMENTS = [
    (["--max-evals", "0"], f"--max-evals must be in [1, {MAX_EVALUATIONS}]"),
    (["--max-evals", str(MAX_EVALUATIONS + 1)], "--max-evals must be in"),
    (["--fraction", "1"], "--fraction must be in (0, 1)"),
    (["--sigma-f", "3"], "need --lag"),
    (["--sigma-v", "-1"], "start of sigma_v must be a positive number"),
    (["--mu", "0.5"], "--mu does not apply to --estimator skf"),
    (["--y", "zz"], "missing column 'zz'"),
]


@pytest.mark.parametrize(("args", "message"), BAD_ARGUMENTS)
def test_bad_arguments_exit_2_with_one_line(
    args: list[str], message: str, small_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["tune", str(small_log), "--estimator", "skf", *SYNTH_AXES, "--y", "y"]
    code, out, err = run(base + args, capsys)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1
    assert err.startswith("mapwise: error: ")
    assert message in err


@pytest.mark.slow
def test_a_log_beyond_the_length_limit_exits_2(tmp_path: Path) -> None:
    """Through a real process: a CSV one sample longer than tune takes."""
    from estimation.tuning import MAX_SAMPLES

    path = tmp_path / "long.csv"
    path.write_text("u,y\n" + "1,1\n" * (MAX_SAMPLES + 1))
    proc = subprocess.run(
        [sys.executable, "-m", "app.cli", "tune", str(path), "--estimator", "skf",
         *SYNTH_AXES, "--y", "y"],
        capture_output=True, text=True, check=False, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert f"tune takes at most {MAX_SAMPLES} samples" in proc.stderr
    assert proc.stderr.count("\n") == 1


# -- the joint EKFs ---------------------------------------------------------------------------


def test_tune_an_ekf_on_a_scenario(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(
        [
            "tune", "--estimator", "ekf-aug", "--scenario", "maf-1d-whtc", "--seed", "3",
            "--duration", "60", "--max-evals", "3", "--sigma-maf-rel", "0.01",
        ],
        capsys,
    )  # fmt: skip
    assert (code, err) == (0, "")
    doc = json.loads(out)
    assert set(doc["parameters"]) == {"sigma_maf_rel", "sigma_maf_abs", "sigma_bias"}
    assert doc["start"]["sigma_maf_rel"] == 0.01
    assert doc["evaluations"] == 3
    assert doc["samples"] == 601
    assert doc["unit"] == "kg/s"
    assert doc["holdout"]["fit_samples"] + doc["holdout"]["holdout_samples"] == 601
    assert math.isfinite(doc["holdout"]["adapted"]["rmse"])


@pytest.fixture(scope="module")
def ekf_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """60 s of ``maf-1d-whtc`` as a CSV with the EKF's default channel names."""
    s = get_scenario("maf-1d-whtc").build(seed=3, duration_s=60.0).signals
    names = ["u_egr_pos_pct", "u_vgt_pos_pct", "fuel_mg_per_cycle", "speed_rpm", "maf_kg_s"]
    rows = ["time," + ",".join(names)]
    rows += [
        f"{t:.2f}," + ",".join(f"{v:.8g}" for v in values)
        for t, *values in zip(s.time, *(s[n] for n in names), strict=True)
    ]
    path = tmp_path_factory.mktemp("tune_ekf") / "airpath.csv"
    path.write_text("\n".join(rows) + "\n")
    return path


def test_tune_an_ekf_on_a_csv_log(ekf_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(
        ["tune", str(ekf_log), "--estimator", "ekf-def", "--max-evals", "2"], capsys
    )
    assert (code, err) == (0, "")
    doc = json.loads(out)
    assert set(doc["parameters"]) == {"sigma_maf_rel", "sigma_maf_abs"}
    assert doc["start"] == {"sigma_maf_rel": 0.01, "sigma_maf_abs": 2e-4}  # EkfConfig's
    assert doc["samples"] == 601


BAD_EKF_ARGUMENTS = [
    (["--estimator", "ekf-aug"], "on a CSV log or on --scenario NAME"),
    (["--estimator", "ekf-aug", "--scenario", "nope"], "nope"),
    (["--estimator", "ekf-aug", "--scenario", "maf-1d-whtc", "--axis", "u=0,1"], "--axis"),
    (["--estimator", "ekf-def", "--scenario", "maf-1d-whtc", "--sigma-bias", "1e-3"], "not"),
    (["--estimator", "ekf-aug", "--scenario", "maf-1d-whtc", "--duration", "-5"], "duration"),
    (["--estimator", "kf", "--scenario", "maf-1d-whtc"], "applies to the EKF"),
    (["--estimator", "ekf-aug", "--seed", "3"], "on a CSV log or on --scenario"),
]


@pytest.mark.parametrize(("args", "message"), BAD_EKF_ARGUMENTS)
def test_bad_ekf_arguments_exit_2_with_one_line(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(["tune", *args, "--max-evals", "1"], capsys)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1
    assert err.startswith("mapwise: error: ")
    assert message in err
