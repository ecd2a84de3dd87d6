"""``mapwise adapt``: the JSON contract, exit codes and one-line errors, through the real CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from estimation.table import Axis, Table

AXES = ["--axis", "u1=500,1500,2500,3500", "--axis", "u2=0,20,40,60"]
TRUE_MAP = Table(
    [Axis("u1", "rpm", [500, 1500, 2500, 3500]), Axis("u2", "mg/stroke", [0, 20, 40, 60])],
    np.add.outer(np.array([1.0, 2.0, 3.5, 3.0]), np.array([0.0, 0.5, 1.5, 1.0])),
)


def write_log(path: Path, n: int = 4000, seed: int = 0, header: str | None = None) -> Path:
    rng = np.random.default_rng(seed)
    u = np.column_stack([rng.uniform(400, 3600, n), rng.uniform(-5, 65, n)])
    y = TRUE_MAP.evaluate(u) + rng.normal(0.0, 0.05, n)
    rows = [header or "time [s],u1 [rpm],u2 [mg/stroke],y [ppm]"]
    rows += [f"{0.02 * k:.2f},{u[k, 0]:.4f},{u[k, 1]:.4f},{y[k]:.5f}" for k in range(n)]
    path.write_text("\n".join(rows) + "\n")
    return path


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def log(tmp_path: Path) -> Path:
    return write_log(tmp_path / "log.csv")


@pytest.mark.parametrize("estimator", ["kf", "skf", "sskf", "rls", "nlms"])
def test_document_follows_contract_and_learns_the_map(
    estimator: str, log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_file = tmp_path / "map.json"
    extra = ["--sigma-w", "0.01", "--p0", "10"] if estimator in ("kf", "skf") else []
    code, out, err = run(
        [
            "adapt", str(log), "--estimator", estimator, *AXES, "--y", "y",
            "--sigma-v", "0.05", *extra, "--json", "--out", str(out_file),
        ],
        capsys,
    )  # fmt: skip
    assert (code, err) == (0, "")
    doc = json.loads(out)
    assert json.loads(out_file.read_text()) == doc
    assert {"estimator", "axes", "values", "variance", "samples", "rejected", "timing"} <= set(doc)
    assert doc["estimator"] == estimator
    assert doc["quantity"] == "y"  # what the map holds: the --y column
    assert doc["axes"] == [a.to_dict() for a in TRUE_MAP.axes]
    assert doc["samples"] == 4000
    assert set(doc["timing"]) >= {"load_s", "estimate_s"}
    values = np.array(doc["values"])
    assert values.shape == (4, 4)
    assert np.max(np.abs(values - TRUE_MAP.values)) < 0.15
    if estimator in ("sskf", "nlms"):
        assert doc["variance"] is None
    else:
        assert np.array(doc["variance"]).shape == (4, 4)


def test_locked_cells_and_gate_are_reported(log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(
        [
            "adapt", str(log), "--estimator", "skf", *AXES, "--y", "y", "--sigma-w", "0.01",
            "--sigma-v", "0.05", "--p0", "10", "--theta0", "7", "--lock", "0,0;3,3",
            "--gate-sigma", "1.5", "--json",
        ],
        capsys,
    )  # fmt: skip
    doc = json.loads(out)
    assert code == 0
    assert doc["values"][0][0] == 7.0
    assert doc["values"][3][3] == 7.0
    assert doc["variance"][0][0] == 10.0
    assert doc["rejected"]["innovation"] > 0
    assert doc["accepted"] == doc["samples"] - sum(doc["rejected"].values())


def test_sensor_delay_in_seconds_uses_the_time_column(
    log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run(
        [
            "adapt", str(log), "--estimator", "kf", *AXES, "--y", "y", "--p0", "1",
            "--lag", "0.5", "--delay-s", "0.1", "--sigma-f", "0.1", "--json",
        ],
        capsys,
    )  # fmt: skip
    assert code == 0
    assert json.loads(out)["rejected"]["delay"] == 5  # 0.1 s at 50 Hz


def test_human_readable_map_by_default(log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(["adapt", str(log), "--estimator", "nlms", *AXES, "--y", "y"], capsys)
    assert code == 0
    assert "rows: u1 [rpm], columns: u2 [mg/stroke]" in out
    assert len(out.strip().splitlines()) == 2 + 1 + 4


BAD_ARGUMENTS = [
    (["--axis", "u1=500", "--y", "y"], "--axis u1: needs at least two breakpoints"),
    (["--axis", "u1=3,2", "--y", "y"], "strictly increasing"),
    (["--axis", "u1=1,2,2", "--y", "y"], "strictly increasing"),
    (["--axis", "u1=a,b", "--y", "y"], "breakpoints must be numbers"),
    (["--axis", "nope=1,2", "--y", "y"], "missing column 'nope'"),
    (["--axis", "u1=1,2", "--y", "zz"], "missing column 'zz'"),
    (["--axis", "u1=1,2", "--y", "y", "--mu", "0.5"], "--mu does not apply to --estimator skf"),
    (["--axis", "u1=1,2", "--y", "y", "--lock", "5"], "locked: cell [5] is not inside"),
    (["--axis", "u1=1,2", "--y", "y", "--lock", "a"], "cells are 0-based integers"),
    (["--axis", "u1=1,2", "--y", "y", "--limit", "p0"], "P0 must be > 0"),
    (["--axis", "u1=1,2", "--y", "y", "--sigma-v", "-1"], "sigma_v"),
    (["--axis", "u1=1,2", "--y", "y", "--lag", "1.5"], "sensor.lag"),
    (["--axis", "u1=1,2", "--y", "y", "--delay-s", "1"], "need --lag"),
    (["--axis", "u1=1,2", "--y", "y", "--sigma-v", "x"], "invalid float value: 'x'"),
    (["--axis", "u1=1,2"], "required: --y"),
]


@pytest.mark.parametrize(("args", "message"), BAD_ARGUMENTS)
def test_bad_arguments_exit_2_with_one_line(
    args: list[str], message: str, log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(["adapt", str(log), "--estimator", "skf", *args], capsys)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1
    assert err.startswith("mapwise: error: ")
    assert message in err


BAD_FILES = [
    ("time,u1,y\n0,1,2\n1,abc,3\n", "line 3, column 'u1': non-numeric value 'abc'"),
    ("time,u1,y\n0,1,2\n1,nan,3\n", "line 3, column 'u1': nan is not allowed"),
    ("time,u1,y\n0,1,2\n1,1,inf\n", "line 3, column 'y': inf is not allowed"),
    ("time,u1,y\n0,1,2\n1,,3\n", "line 3, column 'u1': empty value"),
    ("time,u1,y\n0,1,2\n0,1,3\n", "duplicate time 0 s at line 3"),
    ("time,u1,y\n1,1,2\n0,1,3\n", "decreasing time 0 s at line 3"),
    ("time,u1,y\n0,1,2\n1,2\n", "line 3: 2 fields, header has 3"),
    ("", "empty file"),
    ("time,u1,u1\n0,1,2\n", "duplicate column names ['u1']"),
]


@pytest.mark.parametrize(("content", "message"), BAD_FILES)
def test_bad_files_exit_2_naming_line_and_column(
    content: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(content)
    code, _, err = run(
        ["adapt", str(path), "--estimator", "skf", "--axis", "u1=0,2", "--y", "y"], capsys
    )
    assert code == 2
    assert err.count("\n") == 1
    assert message in err


def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(
        ["adapt", str(tmp_path / "no.csv"), "--estimator", "kf", "--axis", "u=1,2", "--y", "y"],
        capsys,
    )
    assert code == 2
    assert "no such file" in err


def test_console_script_exit_code_and_stderr(tmp_path: Path) -> None:
    """The installed entry point behaves like main(): exit 2, one line on stderr."""
    proc = subprocess.run(
        [sys.executable, "-m", "app.cli", "adapt", str(tmp_path / "x.csv"), "--estimator", "kf",
         "--axis", "u=1,2", "--y", "y"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("mapwise: error:")
    assert proc.stderr.count("\n") == 1


def test_shipped_example_learns_the_nox_map(capsys: pytest.CaptureFixture[str]) -> None:
    """The first-run demo: the SKF learns the visited part of the true NOx map."""
    from estimation.plants.nox import nox_base_map

    example = Path(__file__).resolve().parents[3] / "app" / "data" / "example_nox.csv"
    truth = nox_base_map()
    axes = [f"--axis={a.name}=" + ",".join(f"{b:g}" for b in a.breakpoints) for a in truth.axes]
    code, out, _ = run(
        [
            "adapt", str(example), "--estimator", "skf", *axes, "--y", "nox_ppm",
            "--sigma-w", "15", "--sigma-v", "25", "--p0", "10000", "--lag", "0.96",
            "--delay-s", "0.75", "--sigma-f", "50", "--json",
        ],
        capsys,
    )  # fmt: skip
    assert code == 0
    doc = json.loads(out)
    assert doc["rejected"]["delay"] == 38
    values = np.array(doc["values"])
    log = np.loadtxt(example, delimiter=",", skiprows=1)
    idx, w = truth.regressor(log[:, 1:3])
    visits = np.bincount(idx.ravel(), weights=w.ravel(), minlength=truth.size)
    learned = visits.reshape(truth.shape) > 50  # cells the drive dwelt on (samples of weight)
    assert learned.sum() > 40
    relative = np.abs(values - truth.values)[learned] / np.maximum(truth.values[learned], 100.0)
    assert np.median(relative) < 0.1
