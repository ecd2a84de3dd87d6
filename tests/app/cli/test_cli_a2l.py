"""``mapwise a2l list|show`` and ``mapwise adapt --a2l --map --values``, through the real CLI:
the demo A2L, a HEX image written by bincopy and a CSV drive log whose channels carry the
map's input quantities (one with INCA's ``\\ETK:1`` suffix)."""

from __future__ import annotations

import json
from pathlib import Path

import bincopy
import numpy as np
import pytest

from app.calibration.cdfx import read_cdfx
from app.calibration.values import read_dcm_values
from app.cli import main
from tests.frontend import ecu_files as ef

pytestmark = pytest.mark.slow  # the A2L is parsed by pya2ldb in a child process (seconds)

VALUES = np.array(ef.VALUES, dtype=float)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """The completed demo A2L, a HEX image holding the map, and the drive log."""
    folder = tmp_path_factory.mktemp("ecu")
    a2l, hex_path, _ = ef.write_files(folder)
    log = folder / "drive.csv"
    log.write_text(ef.drive_log(duration_s=30.0))
    return a2l, hex_path, log


@pytest.fixture(autouse=True)
def cache(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MAPWISE_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "a2l-cache"))


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_list_names_every_map_and_curve(files, capsys) -> None:  # type: ignore[no-untyped-def]
    a2l, _, _ = files
    code, out, err = run(["a2l", "list", str(a2l), "--type", "MAP,CURVE", "--json"], capsys)
    assert (code, err) == (0, "")
    doc = json.loads(out)
    types = {item["type"] for item in doc["items"]}
    names = {item["name"] for item in doc["items"]}
    assert types == {"MAP", "CURVE"}
    assert doc["total"] == len(names) >= 12
    assert {ef.MAP_NAME, "ASAM.C.MAP.COM_AXIS.FIX_AXIS", "ASAM.C.CURVE.FIX_AXIS.PAR"} <= names

    code, out, _ = run(["a2l", "list", str(a2l), "--search", "fix axis par_dist"], capsys)
    assert code == 0
    assert "ASAM.C.CURVE.FIX_AXIS.PAR_DIST" in out
    assert "ASAM.C.CURVE.FIX_AXIS.PAR_LIST" not in out
    assert out.strip().endswith("1 characteristic")


def test_show_decodes_the_map_from_the_image(files, capsys) -> None:  # type: ignore[no-untyped-def]
    a2l, hex_path, _ = files
    args = ["a2l", "show", str(a2l), "--map", ef.MAP_NAME, "--values", str(hex_path)]
    code, out, err = run([*args, "--json"], capsys)
    assert (code, err) == (0, "")
    doc = json.loads(out)
    assert doc["shape"] == [4, 5]
    assert np.array_equal(doc["values"]["values"], VALUES)
    assert doc["values"]["axes"][0] == list(map(float, ef.X_POINTS))
    code, out, _ = run(args, capsys)
    assert code == 0
    assert ef.X_QUANTITY in out
    assert "142" in out  # the last cell
    s19 = hex_path.with_suffix(".s19")
    image = bincopy.BinFile()
    image.add_binary(ef.map_record(), address=ef.MAP_ADDRESS)
    s19.write_text(image.as_srec())
    code, out, _ = run([*args[:-1], str(s19), "--json"], capsys)
    assert code == 0
    assert np.array_equal(json.loads(out)["values"]["values"], VALUES)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["show", "--map", "NO.SUCH.MAP"], "no characteristic 'NO.SUCH.MAP'"),
        (["list", "--type", "CUBE"], "--type CUBE"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(files, capsys, extra, message) -> None:  # type: ignore[no-untyped-def]
    a2l, _, _ = files
    code, out, err = run(["a2l", extra[0], str(a2l), *extra[1:]], capsys)
    assert (code, out) == (2, "")
    assert message in err
    assert err.count("\n") == 1


def test_a_corrupt_a2l_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.a2l"
    bad.write_text("/begin MODULE nothing\n")
    code, _, err = run(["a2l", "list", str(bad)], capsys)
    assert code == 2
    assert "A2L" in err


def test_adapt_from_the_a2l_writes_dcm_cdfx_and_the_patched_image(
    files, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:  # type: ignore[no-untyped-def]
    a2l, hex_path, log = files
    out = {k: tmp_path / f"map.{k}" for k in ("dcm", "cdfx", "hex", "json")}
    code, stdout, err = run(
        [
            "adapt", str(log), "--estimator", "skf", "--a2l", str(a2l), "--map", ef.MAP_NAME,
            "--values", str(hex_path), "--y", ef.OUTPUT, "--sigma-v", "0.5", "--sigma-w", "0.05",
            "--p0", "100", "--json", "--out", str(out["json"]), "--out-dcm", str(out["dcm"]),
            "--out-cdfx", str(out["cdfx"]), "--out-image", str(out["hex"]),
        ],
        capsys,
    )  # fmt: skip
    # no error line (stderr may carry a library's warning; the exit code is what counts)
    assert code == 0, err
    assert "mapwise: error" not in err
    doc = json.loads(stdout)
    assert json.loads(out["json"].read_text()) == doc
    # the map document's contract, plus the calibration
    assert {"estimator", "axes", "values", "variance", "samples", "rejected", "timing"} <= set(doc)
    assert [a["name"] for a in doc["axes"]] == [ef.X_CHANNEL, ef.Y_QUANTITY]
    assert [a["breakpoints"] for a in doc["axes"]] == [
        list(map(float, ef.X_POINTS)),
        list(map(float, ef.Y_POINTS)),
    ]
    learned = np.array(doc["values"])
    stored = np.array(doc["calibration"]["values"])
    assert np.array_equal(stored, np.round(learned))
    assert np.allclose(doc["quantization_error"], stored - learned)
    assert np.abs(stored - (VALUES + 15.0)).max() < 3.0  # the log's map: stored + 15 h

    assert np.array_equal(read_dcm_values(out["dcm"].read_bytes())[ef.MAP_NAME].values, stored)
    assert np.array_equal(read_cdfx(out["cdfx"].read_bytes())[ef.MAP_NAME].values, stored)
    before, after = ef.memory(hex_path.read_bytes()), ef.memory(out["hex"].read_bytes())
    assert before.keys() == after.keys()
    changed = [a for a in before if before[a] != after[a]]
    assert changed
    assert all(ef.MAP_ADDRESS <= a < ef.MAP_ADDRESS + len(ef.map_record()) for a in changed)
    code, stdout, _ = run(
        ["a2l", "show", str(a2l), "--map", ef.MAP_NAME, "--values", str(out["hex"]), "--json"],
        capsys,
    )
    assert np.array_equal(json.loads(stdout)["values"]["values"], stored)


def test_adapt_lists_the_quantities_no_channel_matches(
    files, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:  # type: ignore[no-untyped-def]
    a2l, hex_path, _ = files
    log = tmp_path / "other.csv"
    log.write_text("time,rpm,runtime\n0,1,2\n1,2,3\n2,3,4\n")
    code, out, err = run(
        ["adapt", str(log), "--estimator", "skf", "--a2l", str(a2l), "--map", ef.MAP_NAME,
         "--values", str(hex_path), "--y", "runtime"],
        capsys,
    )  # fmt: skip
    assert (code, out) == (2, "")
    assert ef.X_QUANTITY in err
    assert ef.Y_QUANTITY in err
    assert err.count("\n") == 1


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--map", ef.MAP_NAME], "--map needs --a2l"),
        (["--a2l", "{a2l}"], "--a2l needs --map"),
        (["--a2l", "{a2l}", "--map", ef.MAP_NAME, "--out-image", "x.hex"], "--out-image needs"),
        (["--a2l", "{a2l}", "--map", ef.MAP_NAME, "--values", "{a2l}"], "values file"),
        (
            ["--a2l", "{a2l}", "--map", "ASAM.C.SCALAR.FLOAT32_IEEE.IDENTICAL"],
            "only a MAP or CURVE",
        ),
    ],
)
def test_adapt_calibration_flags_exit_2(files, capsys, extra, message) -> None:  # type: ignore[no-untyped-def]
    a2l, _, log = files
    args = [x.replace("{a2l}", str(a2l)) for x in extra]
    code, out, err = run(["adapt", str(log), "--estimator", "skf", "--y", "runtime", *args], capsys)
    assert (code, out) == (2, "")
    assert message in err
    assert err.count("\n") == 1


def _dcm(path: Path, name: str, axes: list, values: np.ndarray) -> Path:
    from app.io.dcm import DcmBlock, blocks_to_dcm

    path.write_text(blocks_to_dcm([DcmBlock(name, axes, values, ef.MAP_UNIT)]))
    return path


def _bad_values(case: str, folder: Path, hex_path: Path) -> tuple[str, Path, str]:
    """``(map, values file, what the error line says)`` of each bad values file."""
    xy = [(ef.X_QUANTITY, "", list(ef.X_POINTS)), (ef.Y_QUANTITY, "", list(ef.Y_POINTS))]
    if case == "hex without the map":
        name = "ASAM.C.CURVE.STD_AXIS"  # its record is not in the image
        return name, hex_path, f"characteristic {name}"
    if case == "dcm axis not the A2L's":
        name = "ASAM.C.CURVE.FIX_AXIS.PAR_DIST"  # FIX_AXIS 0, 20, …, 100
        path = _dcm(folder / "axis.dcm", name, [("x", "", [0, 20, 40, 60, 80, 120])], np.ones(6))
        return name, path, f"DCM {name}: axis X (ASAM.M.SCALAR.SBYTE.IDENTICAL) points"
    high = VALUES.copy()
    high[0, 1] = -40000.0
    path = _dcm(folder / "high.dcm", ef.MAP_NAME, xy, high)
    return (
        ef.MAP_NAME,
        path,
        (f"DCM {ef.MAP_NAME}: cell (0, 1) is -40000.0, below the lower limit of [-32268, 32267]"),
    )


BAD_VALUES = ["hex without the map", "dcm axis not the A2L's", "dcm beyond the limits"]


@pytest.mark.parametrize("case", BAD_VALUES)
def test_bad_values_files_exit_2_and_write_nothing(files, tmp_path, capsys, case) -> None:  # type: ignore[no-untyped-def]
    """``a2l show`` and ``adapt --a2l`` refuse the values with exit 2 and one line naming the
    characteristic and the problem; adapt writes none of its outputs."""
    a2l, hex_path, log = files
    name, values, message = _bad_values(case, tmp_path, hex_path)
    code, out, err = run(["a2l", "show", str(a2l), "--map", name, "--values", str(values)], capsys)
    assert (code, out) == (2, "")
    assert message in err
    assert err.count("\n") == 1
    outputs = [tmp_path / "out.json", tmp_path / "out.dcm", tmp_path / "out.cdfx"]
    code, out, err = run(
        ["adapt", str(log), "--estimator", "skf", "--a2l", str(a2l), "--map", name,
         "--values", str(values), "--y", ef.OUTPUT, "--out", str(outputs[0]),
         "--out-dcm", str(outputs[1]), "--out-cdfx", str(outputs[2])],
        capsys,
    )  # fmt: skip
    assert (code, out) == (2, "")
    assert message in err
    assert err.count("\n") == 1
    assert not any(p.exists() for p in outputs)


def test_an_a2l_the_parser_refuses_exits_2(files, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    """Cut off inside a CHARACTERISTIC, its ends named only in a comment (so past the
    sniff, which refuses a file without them as truncated): pya2ldb's parser refuses it, in
    ``a2l list`` and in ``adapt --a2l``."""
    a2l, _, log = files
    text = a2l.read_bytes()
    cut = tmp_path / "cut.a2l"
    cut.write_bytes(
        text[: text.index(b"/begin CHARACTERISTIC") + 40] + b"\n/* /end MODULE /end PROJECT */\n"
    )
    for args in (
        ["a2l", "list", str(cut)],
        ["adapt", str(log), "--estimator", "skf", "--a2l", str(cut), "--map", ef.MAP_NAME,
         "--y", ef.OUTPUT],
    ):  # fmt: skip
        code, out, err = run(args, capsys)
        assert (code, out) == (2, "")
        assert "the A2L does not parse" in err
        assert err.count("\n") == 1
