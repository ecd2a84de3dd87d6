"""A2L import: every map of the ASAM demo listed, axes/units/limits as in the file text,
search, the parse-once cache, and clear errors for files that are no A2L."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from app.calibration import a2l as a2l_module
from app.calibration.a2l import A2lFile, cached_paths, open_a2l, open_cached
from app.io.errors import InputError
from tests.app.calibration.demo_a2l import FIX_AXIS_VALUES

# A small A2L of our own: a MAP with a FIX_AXIS (linear conversion) and a COM_AXIS, a
# CURVE with FIX_AXIS_PAR, a VALUE, an ASCII (not listed); a characteristic BYTE_ORDER
# that overrides MOD_COMMON's; non-ASCII text in a description and a unit.
MINI_A2L = """ASAP2_VERSION 1 61
/begin PROJECT Mini "mapwise test ECU"
  /begin MODULE Engine ""
    /begin MOD_COMMON ""
      BYTE_ORDER MSB_FIRST
      ALIGNMENT_WORD 2
    /end MOD_COMMON
    /begin RECORD_LAYOUT RL_UWORD
      FNC_VALUES 1 UWORD ROW_DIR DIRECT
    /end RECORD_LAYOUT
    /begin RECORD_LAYOUT RL_AXIS_UBYTE
      AXIS_PTS_X 1 UBYTE INDEX_INCR DIRECT
    /end RECORD_LAYOUT
    /begin COMPU_METHOD CM_IGN "ignition angle" LINEAR "%5.2" "°CRK"
      COEFFS_LINEAR 0.75 -48
    /end COMPU_METHOD
    /begin COMPU_METHOD CM_RPM "" LINEAR "%6.1" "rpm"
      COEFFS_LINEAR 0.25 0
    /end COMPU_METHOD
    /begin COMPU_METHOD CM_LOAD "" RAT_FUNC "%5.2" "%"
      COEFFS 0 2 0 0 0 1
    /end COMPU_METHOD
    /begin AXIS_PTS RL_AX "relative load axis" 0x2000 rl_w RL_AXIS_UBYTE 0 CM_LOAD 3 0 100
    /end AXIS_PTS
    /begin CHARACTERISTIC KFZW "Zündwinkel Grundkennfeld" MAP 0x1000 RL_UWORD 0 CM_IGN -48 60
      /begin AXIS_DESCR FIX_AXIS nmot_w CM_RPM 4 0 8000
        FIX_AXIS_PAR_DIST 0 4000 4
      /end AXIS_DESCR
      /begin AXIS_DESCR COM_AXIS rl_w CM_LOAD 3 0 100
        AXIS_PTS_REF RL_AX
      /end AXIS_DESCR
      BYTE_ORDER MSB_LAST
    /end CHARACTERISTIC
    /begin CHARACTERISTIC KLAMBDA "lambda set point" CURVE 0x1100 RL_UWORD 0 NO_COMPU_METHOD 0 2
      /begin AXIS_DESCR FIX_AXIS tmot NO_COMPU_METHOD 3 -40 140
        FIX_AXIS_PAR 10 3 3
      /end AXIS_DESCR
    /end CHARACTERISTIC
    /begin CHARACTERISTIC ZWOFS "ignition offset" VALUE 0x1200 RL_UWORD 0 CM_IGN -10 10
    /end CHARACTERISTIC
    /begin CHARACTERISTIC SWVERSION "software version" ASCII 0x1300 RL_UWORD 0 NO_COMPU_METHOD 0 255
      NUMBER 8
    /end CHARACTERISTIC
  /end MODULE
/end PROJECT
"""

_BLOCK = re.compile(r"/begin CHARACTERISTIC(.*?)/end CHARACTERISTIC", re.S)
_COMMENT = re.compile(r"/\*.*?\*/", re.S)
_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|\S+')


def scan_characteristics(text: str) -> dict[str, dict[str, object]]:
    """Name → fields of every CHARACTERISTIC, read from the text with a tokenizer that
    knows nothing but the fixed parameter order (independent of pya2ldb)."""
    found = {}
    for block in _BLOCK.findall(text):
        tokens = _TOKEN.findall(_COMMENT.sub(" ", block))
        name, description, kind, address, deposit, _, conversion, lower, upper = tokens[:9]
        found[name] = {
            "description": description.strip('"'),
            "type": kind,
            "address": int(address, 0),
            "record_layout": deposit,
            "compu_method": conversion,
            "limits": [float(lower), float(upper)],
        }
    return found


@pytest.fixture(scope="module")
def mini_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("mini-cache")


@pytest.fixture(scope="module")
def mini_a2l(mini_cache: Path) -> A2lFile:
    """MINI_A2L as UTF-8 with a byte-order mark, parsed once for the module."""
    return open_a2l(b"\xef\xbb\xbf" + MINI_A2L.encode("utf-8"), cache_dir=mini_cache)


@pytest.fixture(scope="module")
def demo_text(demo_a2l_path: Path) -> str:
    return demo_a2l_path.read_text(encoding="latin-1")


def test_every_map_and_curve_of_the_demo_is_listed(demo_a2l: A2lFile, demo_text: str) -> None:
    scanned = scan_characteristics(demo_text)
    maps_and_curves = {n for n, f in scanned.items() if f["type"] in ("MAP", "CURVE")}
    total, listed = demo_a2l.search(types=("MAP", "CURVE"), limit=1000)

    assert len(maps_and_curves) == 12  # 10 CURVEs and 2 MAPs in ASAP2_Demo_V161
    assert {c.name for c in listed} == maps_and_curves
    assert total == len(maps_and_curves)


def test_listed_fields_match_the_file_text(demo_a2l: A2lFile, demo_text: str) -> None:
    scanned = scan_characteristics(demo_text)
    listed_types = {"VALUE", "CURVE", "MAP", "VAL_BLK"}
    wanted = {n: f for n, f in scanned.items() if f["type"] in listed_types}

    assert {c.name for c in demo_a2l.characteristics} == set(wanted)
    for c in demo_a2l.characteristics:
        summary = c.to_json()
        expected = wanted[c.name]
        got = {key: summary[key] for key in expected}
        got["compu_method"] = summary["compu_method"]["name"]
        assert got == expected, c.name
    skipped = sum(1 for f in scanned.values() if f["type"] not in listed_types)
    assert sum(demo_a2l.skipped.values()) == skipped


def test_demo_map_axes_units_and_limits(demo_a2l: A2lFile) -> None:
    summary = demo_a2l.get("ASAM.C.MAP.STD_AXIS.STD_AXIS").to_json()

    assert summary["shape"] == [4, 5]
    assert summary["unit"] == "hours"  # CM.IDENTICAL's unit in the demo
    assert summary["byte_order"] == "MSB_LAST"  # from MOD_COMMON
    x, y = summary["axes"]
    assert (x["attribute"], x["input_quantity"], x["unit"], x["points"], x["limits"]) == (
        "STD_AXIS",
        "ASAM.M.SCALAR.SBYTE.IDENTICAL",
        "hours",
        4,
        [-128.0, 127.0],
    )
    assert (
        y["input_quantity"],
        y["compu_method"]["name"],
        y["compu_method"]["kind"],
        y["points"],
    ) == (
        "ASAM.M.SCALAR.UBYTE.TAB_VERB_NO_DEFAULT_VALUE",
        "CM.TAB_VERB.NO_DEFAULT_VALUE",
        "TAB_VERB",
        5,
    )
    json.dumps(summary, allow_nan=False)  # the REST summary is plain JSON


def test_common_axis_refers_to_its_axis_pts(demo_a2l: A2lFile) -> None:
    curve = demo_a2l.get("ASAM.C.CURVE.COM_AXIS")
    (axis,) = curve.axes

    assert (axis.attribute, axis.axis_pts_ref, axis.points) == (
        "COM_AXIS",
        "ASAM.C.AXIS_PTS.UBYTE_8",
        8,
    )
    pts = demo_a2l.axis_pts["ASAM.C.AXIS_PTS.UBYTE_8"]
    assert (pts.address, pts.max_points, pts.record_layout.name) == (
        8454976,
        8,
        "RL.AXIS_PTS.SBYTE.DECR",
    )


def test_undefined_record_layout_is_listed_but_marked(demo_a2l: A2lFile) -> None:
    curve = demo_a2l.get("ASAM.C.CURVE.STD_AXIS")

    assert curve.record_layout.name == "RL.CURVE.SWORD.SBYTE.DECR"
    assert not curve.record_layout.defined
    assert curve.record_layout.items == ()
    assert curve.datatype == ""
    # pya2ldb's complaints about the demo's TAB_VERB COMPU_TABs survive as warnings with the line
    assert any("TAB_VERB" in w and "5369" in w for w in demo_a2l.warnings)


def test_completed_demo_has_record_layouts_and_fix_axes(full_demo_a2l: A2lFile) -> None:
    layout = full_demo_a2l.get("ASAM.C.MAP.STD_AXIS.STD_AXIS").record_layout

    assert layout.defined
    assert [(i.kind, i.position, i.datatype, i.index_mode) for i in layout.items] == [
        ("NO_AXIS_PTS_X", 1, "UBYTE", ""),
        ("NO_AXIS_PTS_Y", 2, "UBYTE", ""),
        ("AXIS_PTS_X", 3, "SBYTE", "INDEX_INCR"),
        ("AXIS_PTS_Y", 4, "SBYTE", "INDEX_INCR"),
        ("FNC_VALUES", 5, "SWORD", "COLUMN_DIR"),
    ]
    # MOD_COMMON of the demo: ALIGNMENT_FLOAT64_IEEE 4 (not the natural 8)
    assert (
        layout.alignment_of("FLOAT64_IEEE"),
        layout.alignment_of("SWORD"),
        layout.alignment_of("A_INT64"),
    ) == (
        4,
        2,
        8,
    )
    assert full_demo_a2l.get("ASAM.C.MAP.STD_AXIS.STD_AXIS").datatype == "SWORD"
    for name, values in FIX_AXIS_VALUES.items():
        (axis,) = full_demo_a2l.get(name).axes
        assert axis.fix_axis_values == values, name
        assert full_demo_a2l.get(name).shape == (len(values),)


def test_completed_demo_conversions(full_demo_a2l: A2lFile) -> None:
    tab = full_demo_a2l.get("ASAM.C.SCALAR.SWORD.TAB_NOINTP_DEFAULT_VALUE").compu_method
    verbal = full_demo_a2l.get("ASAM.C.SCALAR.SWORD.TAB_VERB_DEFAULT_VALUE").compu_method

    assert tab.kind == "TAB_NOINTP"  # the COMPU_TAB's type decides
    assert tab.table[:3] == ((0.0, 0.0), (1.0, 10.0), (2.0, 20.0))
    assert tab.default_value == 300.56
    assert verbal.verbal == ((0.0, "state_0"), (1.0, "state_1"), (2.0, "state_2"))
    assert verbal.default_text == "unknown signal type"


def test_search_by_name_and_description(demo_a2l: A2lFile) -> None:
    total, hits = demo_a2l.search("std_axis.std_axis")
    assert (total, [c.name for c in hits]) == (1, ["ASAM.C.MAP.STD_AXIS.STD_AXIS"])

    total, hits = demo_a2l.search("RESCALE AXIS")  # description words, any case
    assert [c.name for c in hits] == ["ASAM.C.CURVE.RES_AXIS"]

    assert demo_a2l.search(types="map,CURVE")[0] == 12

    total, hits = demo_a2l.search("curve", types=["map"])
    assert total == 0
    assert hits == []


def test_search_pages_in_name_order(demo_a2l: A2lFile) -> None:
    total, everything = demo_a2l.search(limit=1000)
    _, page = demo_a2l.search(limit=5, offset=10)

    assert total == len(demo_a2l) == len(everything)
    assert page == everything[10:15]
    assert [c.name.lower() for c in everything] == sorted(c.name.lower() for c in everything)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"types": ["SURFACE"]}, "type"),
        ({"limit": -1}, "limit"),
        ({"limit": 10_000}, "limit"),
        ({"offset": -5}, "offset"),
    ],
)
def test_search_rejects_bad_arguments(
    demo_a2l: A2lFile, kwargs: dict[str, object], field: str
) -> None:
    with pytest.raises(InputError) as error:
        demo_a2l.search(**kwargs)  # type: ignore[arg-type]
    assert error.value.field == field


def test_unknown_characteristic_names_it(demo_a2l: A2lFile) -> None:
    with pytest.raises(InputError, match="no characteristic 'KFZW' in the A2L") as error:
        demo_a2l.get("KFZW")
    assert error.value.field == "map"


def test_own_a2l_axes_conversions_byte_order_and_text(mini_a2l: A2lFile) -> None:
    kfzw = mini_a2l.get("KFZW")

    assert (kfzw.description, kfzw.unit, kfzw.byte_order, kfzw.shape) == (
        "Zündwinkel Grundkennfeld",  # UTF-8 (after its byte-order mark) decoded as such
        "°CRK",
        "MSB_LAST",  # its own BYTE_ORDER beats MOD_COMMON's
        (4, 3),
    )
    rpm, load = kfzw.axes
    assert rpm.fix_axis_values == (0.0, 1000.0, 2000.0, 3000.0)  # 0, 4000, … raw × 0.25
    assert (rpm.unit, load.unit, load.axis_pts_ref, load.compu_method.coeffs) == (
        "rpm",
        "%",
        "RL_AX",
        (0, 2, 0, 0, 0, 1),
    )
    assert mini_a2l.get("KLAMBDA").axes[0].fix_axis_values == (10.0, 18.0, 26.0)  # 10 + i·2³
    assert mini_a2l.get("ZWOFS").byte_order == "MSB_FIRST"
    assert mini_a2l.skipped == {"ASCII": 1}
    assert mini_a2l.axis_pts["RL_AX"].datatype == "UBYTE"


def test_second_open_reuses_the_cache_without_pya2ldb(mini_a2l: A2lFile, mini_cache: Path) -> None:
    data = b"\xef\xbb\xbf" + MINI_A2L.encode("utf-8")
    summary, database = cached_paths(mini_a2l.sha256, cache_dir=mini_cache)
    stamp = summary.stat().st_mtime_ns

    assert sorted(p.name for p in mini_cache.iterdir()) == sorted([summary.name, database.name])
    again = open_a2l(data, cache_dir=mini_cache)
    assert again.from_cache
    assert again.characteristics == mini_a2l.characteristics
    assert summary.stat().st_mtime_ns == stamp
    assert open_cached(mini_a2l.sha256, cache_dir=mini_cache) is again  # kept in memory
    assert open_cached("0" * 64, cache_dir=mini_cache) is None
    # A process in which pya2ldb cannot even be imported opens it from the cache.
    script = (
        "import sys; sys.modules['pya2l'] = None\n"
        "from pathlib import Path\n"
        "from app.calibration.a2l import open_a2l\n"
        "a = open_a2l(sys.stdin.buffer.read(), cache_dir=Path(sys.argv[1]))\n"
        "print(a.from_cache, len(a))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script, str(mini_cache)], input=data, capture_output=True, check=True
    )
    assert out.stdout.split() == [b"True", b"3"]


@pytest.mark.slow
def test_unreadable_cache_entry_is_parsed_again_quietly(
    mini_a2l: A2lFile, a2l_cache_dir: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    data = MINI_A2L.encode("latin-1")
    first = open_a2l(data, cache_dir=a2l_cache_dir)
    assert not first.from_cache
    assert first.characteristics == mini_a2l.characteristics  # Latin-1 reads as UTF-8 did
    summary, _ = cached_paths(first.sha256, cache_dir=a2l_cache_dir)
    summary.write_text("{not json", encoding="utf-8")

    again = open_a2l(data, cache_dir=a2l_cache_dir)
    assert not again.from_cache
    assert again.characteristics == first.characteristics
    assert json.loads(summary.read_text(encoding="utf-8"))["version"] == 1
    assert capfd.readouterr() == ("", "")  # pya2ldb's console output stays in the child's log
    assert len(os.listdir(a2l_cache_dir)) == 2  # no temporary directory left behind


@pytest.mark.slow
def test_concurrent_first_opens_agree(a2l_cache_dir: Path) -> None:
    data = MINI_A2L.encode("utf-8")
    results: list[A2lFile] = []
    threads = [
        threading.Thread(target=lambda: results.append(open_a2l(data, cache_dir=a2l_cache_dir)))
        for _ in range(2)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()

    assert len(results) == 2
    assert results[0].characteristics == results[1].characteristics
    assert len(list(a2l_cache_dir.iterdir())) == 2  # one summary, one database, no leftovers


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"", "empty"),
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "binary"),
        (b"hello, this is a text file\n", "no '/begin PROJECT'"),
        pytest.param(
            b'/begin PROJECT P ""\n /begin MODULE M ""\n /begin CHARACTERISTIC\n'
            b"/* /end MODULE /end PROJECT */\n",  # ends named only in a comment: cut mid-block
            "does not parse",
            marks=pytest.mark.slow,  # runs the parser
        ),
        (b'/begin PROJECT P ""\n/end PROJECT\n', "no '/begin MODULE'"),
        (MINI_A2L.encode().split(b"/end MODULE")[0], "ends before '/end MODULE'"),
        (MINI_A2L.encode().rsplit(b"/end PROJECT")[0], "ends before '/end PROJECT'"),
    ],
)
def test_a_file_that_is_no_a2l_is_refused_and_not_cached(
    data: bytes, message: str, a2l_cache_dir: Path
) -> None:
    with pytest.raises(InputError, match=message) as error:
        open_a2l(data, cache_dir=a2l_cache_dir)

    assert error.value.field == "a2l"
    assert error.value.status == 422
    assert list(a2l_cache_dir.iterdir()) == []


def test_too_large_a2l_is_refused(a2l_cache_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(a2l_module, "MAX_A2L_BYTES", 100)
    with pytest.raises(InputError, match="limit is 100") as error:
        open_a2l(MINI_A2L.encode(), cache_dir=a2l_cache_dir)
    assert (error.value.field, error.value.status) == ("a2l", 413)
