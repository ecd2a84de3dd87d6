"""Look-up tables and their sparse regressor (docs/algorithms.md §1) against a slow reference."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation.errors import ShapeError
from estimation.table import Axis, Grid, Table
from tests.estimation import reference as ref
from tests.factories import random_axis

SHAPES = [(2,), (7,), (2, 2), (5, 3), (3, 4, 2), (2, 3, 2, 3)]


def _random_table(rng: np.random.Generator, shape: tuple[int, ...]) -> Table:
    axes = [
        Axis(f"u{a}", "unit", random_axis(rng, n, start=rng.uniform(-50, 50), span=100.0))
        for a, n in enumerate(shape)
    ]
    return Table(axes, rng.normal(size=shape))


def _inputs(rng: np.random.Generator, table: Table, n: int, *, outside: float) -> np.ndarray:
    cols = []
    for axis in table.axes:
        g = axis.breakpoints
        span = g[-1] - g[0]
        cols.append(rng.uniform(g[0] - outside * span, g[-1] + outside * span, n))
    U = np.column_stack(cols)
    # Some inputs exactly on breakpoints (interior and edges).
    for a, axis in enumerate(table.axes):
        U[: axis.size, a] = axis.breakpoints
    return U


@pytest.mark.parametrize("shape", SHAPES)
def test_regressor_matches_the_slow_reference(shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(sum(shape))
    table = _random_table(rng, shape)
    U = _inputs(rng, table, 200, outside=0.3)
    idx, w = table.regressor(U)
    assert idx.shape == w.shape == (200, 2 ** len(shape))
    assert idx.dtype == np.int64
    breakpoints = [a.breakpoints for a in table.axes]
    for k, u in enumerate(U):
        want_idx, want_w, _ = ref.regressor(breakpoints, u)
        assert_array_equal(idx[k], want_idx)
        assert_allclose(w[k], want_w, rtol=1e-12, atol=1e-15)
    assert np.all((w >= 0) & (w <= 1))
    assert_allclose(w.sum(axis=1), 1.0, rtol=1e-12)
    assert np.all((idx >= 0) & (idx < math.prod(shape)))


@pytest.mark.parametrize("shape", SHAPES)
def test_evaluation_matches_the_slow_reference(shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(10 + sum(shape))
    table = _random_table(rng, shape)
    U = _inputs(rng, table, 100, outside=0.3)
    breakpoints = [a.breakpoints for a in table.axes]
    want = [ref.evaluate(breakpoints, table.values, u) for u in U]
    assert_allclose(table.evaluate(U), want, rtol=1e-12, atol=1e-14)
    assert_allclose(table(U), want, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("shape", [(4,), (3, 5), (3, 4, 2)])
def test_a_multilinear_function_is_reproduced_exactly(shape: tuple[int, ...]) -> None:
    """f affine in each input separately (with all cross terms) is its own interpolant."""
    rng = np.random.default_rng(3)
    d = len(shape)
    table = _random_table(rng, shape)
    coef = rng.normal(size=(2,) * d)  # f(u) = Σ_b coef[b] Π_a u_a^{b_a}

    def f(u: np.ndarray) -> np.ndarray:
        out = np.zeros(u.shape[0])
        for bits in np.ndindex(*coef.shape):
            out += coef[bits] * np.prod([u[:, a] ** b for a, b in enumerate(bits)], axis=0)
        return out

    nodes = np.array(list(np.ndindex(*shape)))
    grid_points = np.column_stack([table.axes[a].breakpoints[nodes[:, a]] for a in range(d)])
    exact = table.with_values(f(grid_points).reshape(shape))
    U = _inputs(rng, table, 300, outside=0.0)
    assert_allclose(exact.evaluate(U), f(U), rtol=1e-10, atol=1e-10)
    # Not a tautology: a generic (non-multilinear) function is not reproduced.
    bent = table.with_values((grid_points**2).sum(axis=1).reshape(shape))
    assert np.max(np.abs(bent.evaluate(U) - (U**2).sum(axis=1))) > 1e-3


@pytest.mark.parametrize("shape", [(5,), (4, 3), (3, 2, 4)])
def test_inputs_outside_the_grid_are_clamped(shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(4)
    table = _random_table(rng, shape)
    U = _inputs(rng, table, 200, outside=2.0)
    lo = np.array([a.breakpoints[0] for a in table.axes])
    hi = np.array([a.breakpoints[-1] for a in table.axes])
    assert np.any(lo > U)
    assert np.any(hi < U)
    assert_allclose(table.evaluate(U), table.evaluate(np.clip(U, lo, hi)), rtol=1e-13)
    # Far outside is the edge value exactly.
    far = np.array([hi + 1e6, lo - 1e6])
    corners = table.values[(-1,) * len(shape)], table.values[(0,) * len(shape)]
    assert_allclose(table.evaluate(far), corners, rtol=1e-13)


def test_values_on_the_nodes_are_returned_exactly() -> None:
    rng = np.random.default_rng(5)
    table = _random_table(rng, (4, 3))
    nodes = np.array(list(np.ndindex(*table.shape)))
    U = np.column_stack([table.axes[a].breakpoints[nodes[:, a]] for a in range(2)])
    assert_array_equal(table.evaluate(U), table.values.ravel())


def test_docstring_example_and_1d_inputs() -> None:
    t = Table(
        [Axis("speed", "rpm", [1000, 2000]), Axis("fuel", "mg/cycle", [0, 10, 20])],
        [[0.0, 1.0, 2.0], [10.0, 11.0, 12.0]],
    )
    assert float(t.evaluate([[1500.0, 5.0]])[0]) == 5.5
    line = Table([Axis("x", "", [0.0, 2.0, 3.0])], [0.0, 4.0, 1.0])
    assert_allclose(line.evaluate(np.array([-1.0, 1.0, 2.5, 9.0])), [0.0, 2.0, 2.5, 1.0])


def test_json_round_trip() -> None:
    rng = np.random.default_rng(6)
    table = _random_table(rng, (3, 4, 2))
    back = Table.from_dict(json.loads(json.dumps(table.to_dict())))
    assert back == table
    assert_array_equal(back.values, table.values)
    for a, b in zip(back.axes, table.axes, strict=True):
        assert (a.name, a.unit) == (b.name, b.unit)
        assert_array_equal(a.breakpoints, b.breakpoints)
    assert back != table.with_values(table.values + 1e-15)


@pytest.mark.parametrize(
    ("breakpoints", "match"),
    [
        ([0.0, 2.0, 1.0], "unsorted at positions 1 and 2"),
        ([0.0, 1.0, 1.0, 2.0], "duplicate at positions 1 and 2"),
        ([1.0], "at least two breakpoints, got 1"),
        ([], "at least two breakpoints, got 0"),
        ([0.0, np.inf], "finite"),
        ([0.0, np.nan, 2.0], "finite"),
        ([[0.0, 1.0], [2.0, 3.0]], "1-D"),
        ([-1.7e308, 1.7e308], "beyond the float64 range"),
    ],
)
def test_bad_breakpoints_are_refused(breakpoints: list, match: str) -> None:
    with pytest.raises(ShapeError, match=match):
        Axis("speed", "rpm", breakpoints)
    with pytest.raises(ValueError, match="speed"):  # ShapeError is a ValueError, names the axis
        Axis("speed", "rpm", breakpoints)


def test_bad_values_are_refused() -> None:
    axes = [Axis("a", "", [0, 1, 2]), Axis("b", "", [0, 1])]
    with pytest.raises(
        ShapeError, match=r"expected a scalar or shape \(3, 2\), got shape \(2, 3\)"
    ):
        Table(axes, np.zeros((2, 3)))
    with pytest.raises(ShapeError, match=r"got shape \(5,\)"):
        Table(axes, np.zeros(5))
    values = np.zeros((3, 2))
    values[2, 1] = np.nan
    with pytest.raises(ShapeError, match=r"non-finite value nan at cell \(2, 1\)"):
        Table(axes, values)
    with pytest.raises(ShapeError, match="not numeric"):
        Table(axes, "abc")
    # A flat C-order vector and a scalar are accepted.
    assert_array_equal(Table(axes, np.arange(6.0)).values, np.arange(6.0).reshape(3, 2))
    assert_array_equal(Table(axes, 2.5).values, np.full((3, 2), 2.5))


def test_bad_inputs_and_grids_are_refused() -> None:
    table = Table([Axis("a", "", [0, 1, 2]), Axis("b", "", [0, 1])], 0.0)
    with pytest.raises(ShapeError, match=r"shape \(n, 2\)"):
        table.evaluate(np.zeros((4, 3)))
    with pytest.raises(ShapeError, match="'b' is not finite at sample 1"):
        table.evaluate([[0.0, 0.0], [0.5, np.nan]])
    with pytest.raises(ShapeError, match="unique"):
        Grid([Axis("a", "", [0, 1]), Axis("a", "", [0, 1])])
    with pytest.raises(ShapeError, match="at least one axis"):
        Grid([])
    with pytest.raises(ShapeError, match=r"out of range 0\.\.1 on axis 'b'"):
        table.cell_index([0, 2])
    assert table.cell_index([2, 1]) == 5
    with pytest.raises(ShapeError, match="'axes' and 'values'"):
        Table.from_dict({"axes": []})


@pytest.mark.parametrize("shape", [(9,), (12, 18), (4, 5, 6), (3, 2, 3, 2)])
def test_the_specialised_regressor_is_bit_identical_on_drive_and_jumping_inputs(
    shape: tuple[int, ...],
) -> None:
    """The kernel compiled per dimension, searching from the previous sample's cell, gives
    the generic kernel's idx and w bit for bit: on a slow drive (the hint mostly right), on
    independent draws (mostly wrong), and on breakpoints and outside the table."""
    rng = np.random.default_rng(len(shape))
    table = _random_table(rng, shape)
    jumping = _inputs(rng, table, 3000, outside=0.2)
    lo = np.array([a.breakpoints[0] for a in table.axes])
    span = np.array([a.breakpoints[-1] - a.breakpoints[0] for a in table.axes])
    walk = np.cumsum(rng.normal(0.0, 0.01, (3000, len(shape))), axis=0)
    drive = lo + span * (np.abs((walk + 0.5) % 2.4 - 1.2) - 0.1)  # in and out of the table
    for U in (jumping, drive):
        idx, w = table.regressor(U)
        want_idx, want_w = table.regressor(U, specialised=False)
        assert_array_equal(idx, want_idx)
        assert_array_equal(w, want_w)
        for k in range(0, 3000, 97):  # and the slow reference, on a sample of rows
            ref_idx, ref_w, _ = ref.regressor([a.breakpoints for a in table.axes], U[k])
            assert_array_equal(idx[k], ref_idx)
            assert_allclose(w[k], ref_w, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("shape", SHAPES)
def test_on_grid_matches_the_slow_reference_on_every_node(shape: tuple[int, ...]) -> None:
    """The numpy resampling onto a tensor grid (beyond the box, between and on the nodes)
    equals the slow reference at each node of the target grid."""
    rng = np.random.default_rng(20 + sum(shape))
    table = _random_table(rng, shape)
    targets = []
    for axis in table.axes:
        g = axis.breakpoints
        span = g[-1] - g[0]
        inside = rng.uniform(g[0] - 0.3 * span, g[-1] + 0.3 * span, 3)
        targets.append(np.sort(np.concatenate([inside, g[[0, -1]], g[:1] - span])))
    got = table.on_grid(targets)
    assert got.shape == tuple(t.size for t in targets)
    breakpoints = [a.breakpoints for a in table.axes]
    for node in np.ndindex(got.shape):
        u = np.array([t[k] for t, k in zip(targets, node, strict=True)])
        assert_allclose(
            got[node], ref.evaluate(breakpoints, table.values, u), rtol=1e-12, atol=1e-14
        )


def test_on_grid_gives_the_nodes_exactly_and_refuses_a_wrong_grid() -> None:
    table = _random_table(np.random.default_rng(3), (4, 3, 5))
    assert_array_equal(table.on_grid([a.breakpoints for a in table.axes]), table.values)
    with pytest.raises(ShapeError, match="3 breakpoint arrays"):
        table.on_grid([table.axes[0].breakpoints])
