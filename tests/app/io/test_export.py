"""Map and series exports: CSV and DCM round trips, formula neutralisation and exact
numbers (property tests), and imports of a starting map with errors naming line/field."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.io.errors import InputError
from app.io.export import (
    format_number,
    import_map,
    map_from_csv,
    map_from_dcm,
    map_from_json,
    map_to_csv,
    map_to_dcm,
    maps_to_dcm,
    neutralise,
    series_to_csv,
)
from app.io.ingest import ingest
from estimation.table import Axis, Table

RNG = np.random.default_rng(0)
MAP_2D = Table(
    [Axis("speed", "rpm", [600.0, 1500.5, 2500.0, 4000.0]), Axis("fuel", "mg/stroke", [0, 25, 50])],
    RNG.normal(0, 1e3, (4, 3)),
)
MAP_1D = Table([Axis("=lambda", "", np.linspace(0.7, 1.3, 13))], -RNG.uniform(0, 1e-9, 13))


def bitwise_equal(a: Table, b: Table) -> bool:
    """Axes (names, units, breakpoints) and values identical to the last bit (sign of 0)."""
    return [(x.name, x.unit, x.breakpoints.tobytes()) for x in a.axes] == [
        (x.name, x.unit, x.breakpoints.tobytes()) for x in b.axes
    ] and a.values.tobytes() == b.values.tobytes()


def test_csv_grid_layout() -> None:
    rows = list(csv.reader(io.StringIO(map_to_csv(MAP_2D))))
    assert rows[0][0] == "speed [rpm] \\ fuel [mg/stroke]"
    assert [float(c) for c in rows[0][1:]] == [0.0, 25.0, 50.0]
    assert [float(r[0]) for r in rows[1:]] == [600.0, 1500.5, 2500.0, 4000.0]
    assert float(rows[2][3]) == MAP_2D.values[1, 2]
    rows = list(csv.reader(io.StringIO(map_to_csv(MAP_1D, value_name="k", value_unit="-"))))
    assert rows[0] == ["'=lambda", "k [-]"]  # formula neutralised
    assert len(rows) == 14
    assert all(len(r) == 2 for r in rows)


@pytest.mark.parametrize("table", [MAP_2D, MAP_1D], ids=["2d", "1d"])
def test_csv_and_dcm_round_trips_are_bit_exact(table: Table) -> None:
    assert bitwise_equal(map_from_csv(map_to_csv(table)), table)
    assert bitwise_equal(import_map(map_to_csv(table).encode()), table)
    name, unit, back = map_from_dcm(map_to_dcm(table, name="nox_map", unit="ppm"))
    assert (name, unit) == ("nox_map", "ppm")
    assert bitwise_equal(back, table)
    assert bitwise_equal(import_map(map_to_dcm(table, name="m").encode()), table)


def test_negative_zero_survives_both_formats() -> None:
    table = Table([Axis("x", "", [-1.0, 0.0])], [-0.0, 0.0])
    assert bitwise_equal(map_from_csv(map_to_csv(table)), table)
    assert bitwise_equal(map_from_dcm(map_to_dcm(table, name="c"))[2], table)


def test_dcm_layout_x_is_the_first_axis() -> None:
    text = map_to_dcm(MAP_2D, name="nox_map", unit="ppm", description='raw "NOx"')
    lines = [ln.strip() for ln in text.splitlines()]
    assert "KONSERVIERUNG_FORMAT 2.0" in lines
    assert "KENNFELD nox_map 4 3" in lines
    assert "LANGNAME \"raw 'NOx'\"" in lines
    assert lines[lines.index("ST/Y  25.0") + 1].split()[1:] == [
        repr(float(v)) for v in MAP_2D.values[:, 1]
    ]
    assert "END" in lines


def test_latin1_dcm_from_an_older_tool() -> None:
    text = map_to_dcm(MAP_1D, name="c", unit="°C")
    assert map_from_dcm(text.encode("latin-1"))[1] == "°C"
    assert map_from_dcm(text.encode())[1] == "°C"


def test_dcm_with_several_blocks_and_foreign_blocks() -> None:
    text = (
        "FESTWERT k_gain\n   WERT 1.5\nEND\n\n"
        + maps_to_dcm([("a_map", MAP_2D, "ppm"), ("b_curve", MAP_1D, "")])
        + '\nFUNKTIONEN\n   FKT f1 "" ""\nEND\n'
    )
    assert bitwise_equal(map_from_dcm(text, name="b_curve")[2], MAP_1D)
    with pytest.raises(InputError, match=r"holds 2 maps \['a_map', 'b_curve'\]") as info:
        map_from_dcm(text)
    assert info.value.field == "name"
    with pytest.raises(InputError, match="no map 'zz'"):
        map_from_dcm(text, name="zz")


def test_dcm_from_a_calibration_tool_without_axis_names() -> None:
    text = """* exported by INCA
KONSERVIERUNG_FORMAT 2.0
KENNFELD KF_TEST 3 2
   LANGNAME "test map, driver's side"
   DISPLAYNAME kf_test's
   EINHEIT_X "U/min"
   EINHEIT_Y "-"
   EINHEIT_W "Nm"
   ST/X   1000.0   2000.0
   ST/X   3000.0
   ST/Y   0.0
   WERT   1.0   2.0   3.0
   ST/Y   1.0
   WERT   4.0   5.0
   WERT   6.0
END
"""
    name, unit, table = map_from_dcm(text)
    assert (name, unit) == ("KF_TEST", "Nm")
    assert [(a.name, a.unit) for a in table.axes] == [("x", "U/min"), ("y", "-")]
    np.testing.assert_array_equal(table.values, [[1, 4], [2, 5], [3, 6]])


BAD_DCM = [
    ("KENNLINIE c 3\n ST/X 1 2 3\n WERT 1 2\nEND\n", "line 1", "2 WERT values, expected 3"),
    ("KENNLINIE c 3\n ST/X 1 2\n WERT 1 2 3\nEND\n", "line 1", "2 ST/X values, the header says 3"),
    (
        "KENNFELD m 2 2\n ST/X 1 2\n ST/Y 0\n WERT 1 2\n ST/Y 1\n WERT 1\nEND\n",
        "line 1",
        "1 WERT values after ST/Y 1.0, expected 2",
    ),
    ("KENNFELD m 2 2\n ST/X 1 2\n WERT 1 2\nEND\n", "line 3", "WERT before the first ST/Y"),
    ("KENNLINIE c 2\n ST/X 1 x\n WERT 1 2\nEND\n", "line 2", "non-numeric value 'x'"),
    ("KENNLINIE c 2\n ST/X 1 2\n WERT 1 nan\nEND\n", "line 3", "nan is not allowed"),
    ("KENNLINIE c 2\n ST/X 2 1\n WERT 1 2\nEND\n", "line 1", "strictly increasing"),
    ("KENNLINIE c 2\n ST/X 1 2\n WERT 1 2\n", "line 1", "has no END"),
    ("KENNLINIE c two\nEND\n", "line 1", "sizes must be integers"),
    ('KENNLINIE c 2\n ST_TX/X "a" "b"\nEND\n', "line 2", "text values"),
    ("HELLO world\n", "line 1", "unexpected 'HELLO' outside a block"),
    ('KENNLINIE c 2\n EINHEIT_X "rpm\n ST/X 1 2\nEND\n', "line 2", "unterminated string"),
]


@pytest.mark.parametrize(("text", "field", "message"), BAD_DCM)
def test_bad_dcm_names_the_line(text: str, field: str, message: str) -> None:
    with pytest.raises(InputError) as info:
        map_from_dcm(text)
    assert info.value.field == field
    assert message in info.value.message
    assert info.value.line == int(field.split()[1])


def test_dcm_export_refuses_bad_names_and_3d() -> None:
    with pytest.raises(InputError) as info:
        map_to_dcm(MAP_1D, name="has space")
    assert info.value.field == "name"
    cube = Table([Axis(n, "", [0, 1]) for n in "abc"], 0.0)
    with pytest.raises(InputError, match="3 axes"):
        map_to_dcm(cube, name="c")
    with pytest.raises(InputError, match="3 axes"):
        map_to_csv(cube)


def test_json_import_of_the_adapt_document() -> None:
    document = {
        "estimator": "skf",
        "axes": [a.to_dict() for a in MAP_2D.axes],
        "values": MAP_2D.values.tolist(),
        "variance": None,
        "samples": 10,
        "rejected": {},
        "timing": {"estimate_s": 0.1},
    }
    assert bitwise_equal(map_from_json(json.dumps(document)), MAP_2D)
    assert bitwise_equal(import_map(json.dumps(document).encode()), MAP_2D)
    assert bitwise_equal(map_from_json(document), MAP_2D)


BAD_JSON = [
    ('{"axes": [}', "file", "line 1, column 11: invalid JSON"),
    ("[1, 2]", "file", "JSON object"),
    ('{"values": [1, 2]}', "axes", "non-empty list"),
    ('{"axes": [{"name": "x", "breakpoints": [1, 2]}]}', "values", "no 'values'"),
    ('{"axes": [{"name": "", "breakpoints": [1, 2]}], "values": [1, 2]}', "axes[0].name", ""),
    (
        '{"axes": [{"name": "x", "unit": 3, "breakpoints": [1, 2]}], "values": [1, 2]}',
        "axes[0].unit",
        "",
    ),
    (
        '{"axes": [{"name": "x", "breakpoints": [1, "a"]}], "values": [1, 2]}',
        "axes[0].breakpoints",
        "list of numbers",
    ),
    (
        '{"axes": [{"name": "x", "breakpoints": [2, 1]}], "values": [1, 2]}',
        "axes[0].breakpoints",
        "strictly increasing",
    ),
    (
        '{"axes": [{"name": "x", "breakpoints": [1, 2]}], "values": [1, 2, 3]}',
        "values",
        "expected a scalar or shape (2,)",
    ),
    (
        '{"axes": [{"name": "x", "breakpoints": [1, 2]}], "values": [1, NaN]}',
        "values",
        "non-finite",
    ),
    (
        '{"axes": [{"name": "x", "breakpoints": [1, 2]}], "values": [1, null]}',
        "values[1]",
        "None is not a number",
    ),
    (
        '{"axes": [{"name": "x", "breakpoints": [1, 2]}], "values": [[1], [true]]}',
        "values[1][0]",
        "True is not a number",
    ),
]


@pytest.mark.parametrize(("text", "field", "message"), BAD_JSON)
def test_bad_json_map_names_the_field(text: str, field: str, message: str) -> None:
    with pytest.raises(InputError) as info:
        map_from_json(text)
    assert info.value.field == field
    assert message in info.value.message


BAD_CSV = [
    ("x \\ y,0,1\n0,1,2\n1,2\n", "line 3", "2 fields, the header has 3"),
    ("x \\ y,0,1\n0,1,2\n1,2,abc\n", "line 3", "line 3, column 3: non-numeric value 'abc'"),
    ("x \\ y,0,1\n0,1,2\n1,2,\n", "line 3", "empty cell"),
    ("x \\ y,0,1\n0,1,2\n1,2,inf\n", "line 3", "inf is not allowed"),
    ("x \\ y,0,0\n0,1,2\n1,2,3\n", "axes[1].breakpoints", "strictly increasing"),
    ("x \\ y,0,1\n1,1,2\n0,2,3\n", "axes[0].breakpoints", "strictly increasing"),
    ("x,0,1\n0,1,2\n1,2,3\n", "line 1", "must name both axes"),
    ("x,v\n0,1\n", "file", "at least two rows"),
    ("", "file", "empty map file"),
]


@pytest.mark.parametrize(("text", "field", "message"), BAD_CSV)
def test_bad_csv_map_names_line_and_field(text: str, field: str, message: str) -> None:
    with pytest.raises(InputError) as info:
        map_from_csv(text)
    assert info.value.field == field
    assert message in info.value.message


def test_csv_map_with_semicolons_and_decimal_commas() -> None:
    table = map_from_csv("speed [rpm] \\ fuel;0;10,5\n1000;1,25;2\n2000;3;-4,5\n")
    assert table.axes[1].breakpoints.tolist() == [0.0, 10.5]
    np.testing.assert_array_equal(table.values, [[1.25, 2.0], [3.0, -4.5]])


def test_import_map_refuses_binary() -> None:
    with pytest.raises(InputError) as info:
        import_map(bytes(range(256)))
    assert info.value.code == "unsupported_format"


def test_series_csv_reads_back_exactly_through_ingest() -> None:
    t = np.arange(50) * 0.02
    channels = {"rpm": ("1/min", RNG.uniform(-1e6, 1e6, 50)), "@cmd": ("", -RNG.random(50))}
    text = series_to_csv(t, channels)
    assert text.splitlines()[0] == "time [s],rpm [1/min],'@cmd"
    ds = ingest(text.encode())
    np.testing.assert_array_equal(ds.signals.time, t)
    np.testing.assert_array_equal(ds.signals["rpm"], channels["rpm"][1])
    np.testing.assert_array_equal(ds.signals["'@cmd"], channels["@cmd"][1])


FORMULA_START = st.sampled_from(["=", "+", "-", "@", "\t", "\r"])


@given(st.text())
def test_neutralised_cells_never_start_like_a_formula(text: str) -> None:
    out = neutralise(text)
    assert not out.startswith(("=", "+", "-", "@", "\t", "\r"))
    assert out in (text, "'" + text)


@given(FORMULA_START, st.text())
def test_formula_cells_are_prefixed_and_survive_a_csv_round_trip(start: str, rest: str) -> None:
    cell = start + rest
    written = io.StringIO()
    csv.writer(written).writerow([neutralise(cell), format_number(1.0)])
    (row,) = list(csv.reader(io.StringIO(written.getvalue(), newline="")))
    assert row[0] == "'" + cell


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_numbers_round_trip_exactly(x: float) -> None:
    text = format_number(x)
    assert np.float64(float(text)).tobytes() == np.float64(x).tobytes()
    assert not text.startswith(("=", "+", "@"))


@given(
    st.lists(
        # An axis must span less than the float64 range (estimation.table.Axis refuses more).
        st.floats(min_value=-1e307, max_value=1e307, allow_nan=False, width=64),
        min_size=2,
        max_size=20,
        unique=True,
    ),
    st.floats(allow_nan=False, allow_infinity=False),
)
def test_any_finite_1d_map_round_trips_through_csv_and_dcm(
    breakpoints: list[float], scale: float
) -> None:
    axis = Axis("x", "u", sorted(breakpoints))
    table = Table([axis], np.linspace(-1.0, 1.0, len(breakpoints)) * scale)
    assert bitwise_equal(map_from_csv(map_to_csv(table)), table)
    assert bitwise_equal(map_from_dcm(map_to_dcm(table, name="c"))[2], table)


def test_non_finite_numbers_are_written_explicitly() -> None:
    assert [format_number(v) for v in (np.nan, np.inf, -np.inf)] == ["nan", "inf", "-inf"]
