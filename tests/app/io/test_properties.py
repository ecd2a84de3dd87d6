"""Property tests (hypothesis) of the table regressor and the map importers.

* For any strictly increasing axes and any inputs: at most 2^d weights per sample, all in
  [0, 1], summing to 1, on cells adjacent to the (clamped) input; interpolation of a
  multilinear function is exact; clamping makes outside inputs equal to edge inputs.
* Any map written as CSV, DCM or the JSON document imports back to the identical table;
  arbitrary bytes given to the importers raise InputError (a 4xx), never anything else.
"""

from __future__ import annotations

import json

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.io.errors import InputError
from app.io.export import import_map, map_to_csv, map_to_dcm
from estimation.table import Axis, Grid, Table

FINITE = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


@st.composite
def breakpoints(draw: st.DrawFn, max_size: int = 6) -> list[float]:
    values = draw(st.lists(FINITE, min_size=2, max_size=max_size, unique=True))
    values = sorted(values)
    gaps = np.diff(values)
    if np.any(gaps < 1e-6 * (1 + np.abs(values[1:]))):  # too close to interpolate sensibly
        values = [float(i) * 10.0 for i in range(len(values))]
    return values


@st.composite
def tables(draw: st.DrawFn, max_dims: int = 2) -> Table:
    d = draw(st.integers(min_value=1, max_value=max_dims))
    axes = [
        Axis(f"u{i}", draw(st.sampled_from(["rpm", "mg", ""])), draw(breakpoints()))
        for i in range(d)
    ]
    shape = tuple(a.size for a in axes)
    flat = draw(st.lists(FINITE, min_size=int(np.prod(shape)), max_size=int(np.prod(shape))))
    return Table(axes, np.array(flat, dtype=np.float64).reshape(shape))


@st.composite
def grids_and_inputs(draw: st.DrawFn) -> tuple[Grid, np.ndarray]:
    d = draw(st.integers(min_value=1, max_value=3))
    axes = [Axis(f"u{i}", "", draw(breakpoints(max_size=5))) for i in range(d)]
    n = draw(st.integers(min_value=1, max_value=20))
    lo = min(a.breakpoints[0] for a in axes) - 100.0
    hi = max(a.breakpoints[-1] for a in axes) + 100.0
    rows = draw(
        st.lists(
            st.lists(st.floats(lo, hi, allow_nan=False), min_size=d, max_size=d),
            min_size=n,
            max_size=n,
        )
    )
    return Grid(axes), np.array(rows, dtype=np.float64)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grids_and_inputs())
def test_regressor_weights_are_a_partition_of_unity_on_adjacent_cells(case) -> None:  # type: ignore[no-untyped-def]
    grid, U = case
    idx, w = grid.regressor(U)
    d = len(grid.axes)
    assert idx.shape == w.shape == (len(U), 2**d)
    assert np.all((w >= -1e-12) & (w <= 1 + 1e-12))
    np.testing.assert_allclose(w.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    for i, axis in enumerate(grid.axes):
        x = np.clip(U[:, i], axis.breakpoints[0], axis.breakpoints[-1])
        cell = np.clip(np.searchsorted(axis.breakpoints, x, side="right") - 1, 0, axis.size - 2)
        along = np.array(np.unravel_index(idx, grid.shape))[i]  # (n, 2^d) index on axis i
        touched = w > 0
        assert np.all(~touched | (along == cell[:, None]) | (along == cell[:, None] + 1))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grids_and_inputs(), st.lists(FINITE, min_size=4, max_size=4))
def test_multilinear_functions_are_interpolated_exactly_and_outside_is_clamped(case, c) -> None:  # type: ignore[no-untyped-def]
    grid, U = case
    d = len(grid.axes)
    coef = np.array(c[: d + 1])

    def f(x: np.ndarray) -> np.ndarray:  # affine: multilinear on every cell
        return coef[0] + x @ coef[1 : d + 1]

    nodes = np.stack(np.meshgrid(*[a.breakpoints for a in grid.axes], indexing="ij"), axis=-1)
    table = Table(list(grid.axes), f(nodes.reshape(-1, d)).reshape(grid.shape))
    clamped = np.column_stack(
        [np.clip(U[:, i], a.breakpoints[0], a.breakpoints[-1]) for i, a in enumerate(grid.axes)]
    )
    scale = 1.0 + np.abs(coef).sum() * (1.0 + np.abs(clamped).max())
    np.testing.assert_allclose(table.evaluate(U), f(clamped), rtol=0, atol=1e-9 * scale)
    np.testing.assert_array_equal(table.evaluate(U), table.evaluate(clamped))


@settings(max_examples=80, deadline=None)
@given(tables())
def test_every_export_format_imports_back_to_the_same_table(table: Table) -> None:
    csv_text = map_to_csv(table)
    dcm_text = map_to_dcm(table, name="prop_map", unit="ppm")
    doc = {
        "axes": [a.to_dict() for a in table.axes],
        "values": table.values.tolist(),
    }
    for data in (csv_text.encode(), dcm_text.encode(), json.dumps(doc).encode()):
        back = import_map(data)
        assert [a.size for a in back.axes] == [a.size for a in table.axes]
        for mine, theirs in zip(back.axes, table.axes, strict=True):
            np.testing.assert_array_equal(mine.breakpoints, theirs.breakpoints)
        np.testing.assert_array_equal(back.values, table.values)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400) | st.text(max_size=400).map(str.encode))
def test_importers_refuse_garbage_with_an_input_error_only(data: bytes) -> None:
    error: InputError | None = None
    try:
        import_map(data)
    except InputError as exc:
        error = exc
    if error is not None:
        assert error.status in (413, 415, 422)
        assert error.message
