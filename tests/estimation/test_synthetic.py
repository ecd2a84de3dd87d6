"""The SKF paper's synthetic checks (SKF §5, (20)–(22); docs/algorithms.md §2.7) as data."""

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation import ConfigError, Table
from estimation.plants.synthetic import (
    SIM2_AREAS_PAPER,
    SIM2_EXCITED_ELEMENTS_PAPER,
    SKF_SIM_FILTER_SETTINGS,
    skf_sim,
    skf_sim_table,
)


def test_grid_and_true_table() -> None:
    table = skf_sim_table()
    assert table.shape == (4, 4)
    assert table.axes[0].breakpoints.tolist() == [500, 1500, 2500, 3500]
    assert table.axes[1].breakpoints.tolist() == [0, 20, 40, 60]
    assert [a.name for a in table.axes] == ["u1", "u2"]
    assert_array_equal(table.values, np.ones((4, 4)))


def test_filter_settings_of_the_paper() -> None:
    assert SKF_SIM_FILTER_SETTINGS.to_dict() == {
        "theta0": 0.0,
        "P0": 0.0,
        "sigma_v2": 1.0,
        "sigma_w2": 1.0,
    }


@pytest.mark.parametrize(("number", "length"), [(1, 1400), (2, 200), (3, 200)])
def test_lengths_and_time_base(number: int, length: int) -> None:
    signals, truth = skf_sim(number, seed=0)
    assert len(signals) == length
    assert signals.names == ["u1", "u2", "y"]
    assert_array_equal(signals.time, np.arange(1, length + 1))  # 1 Hz, t = k
    assert signals.sample_period() == 1.0
    assert truth.number == number
    assert truth.table == skf_sim_table()


def test_sim1_uniform_over_the_grid() -> None:
    signals, truth = skf_sim(1, seed=0)
    u1, u2 = signals["u1"], signals["u2"]
    assert u1.min() >= 500.0
    assert u1.max() <= 3500.0
    assert u2.min() >= 0.0
    assert u2.max() <= 60.0
    # uniform: each of the 9 areas gets about 1400/9 ≈ 156 samples (binomial SD ≈ 11.7)
    counts, _, _ = np.histogram2d(u1, u2, bins=[[500, 1500, 2500, 3500], [0, 20, 40, 60]])
    assert counts.sum() == 1400
    assert np.all(np.abs(counts - 1400 / 9) < 50)
    assert_array_equal(signals["y"], 1.0)
    assert_array_equal(truth.noise, 0.0)
    assert truth.excited_cells == tuple(range(16))
    assert_allclose(truth.table.evaluate(signals.stack(["u1", "u2"])), 1.0, rtol=1e-15)


@pytest.mark.parametrize("number", [2, 3])
def test_sim2_sweep(number: int) -> None:
    signals, _ = skf_sim(number, seed=0)
    u1, u2 = signals["u1"], signals["u2"]
    assert_array_equal(u1, 2000.0)
    k = np.arange(1, 201)
    assert_allclose(u2, 60.0 - np.abs(0.6 * k - 60.0), atol=1e-12)
    assert u2[99] == 60.0  # k = 100
    assert u2[-1] == 0.0  # k = 200
    assert u2.min() == 0.0
    assert u2.max() == 60.0
    assert np.all(np.diff(u2[:100]) > 0)  # up in 100 steps
    assert np.all(np.diff(u2[99:]) < 0)  # down in 100 steps
    assert_allclose(np.abs(np.diff(u2)), 0.6, atol=1e-12)


@pytest.mark.parametrize("number", [2, 3])
def test_sim2_excites_the_paper_cells(number: int) -> None:
    signals, truth = skf_sim(number, seed=0)
    table = truth.table
    # paper numbering is 1-based row by row; C order flat index = element − 1
    paper = [e - 1 for e in SIM2_EXCITED_ELEMENTS_PAPER]
    assert truth.excited_cells == tuple(paper) == tuple(range(4, 12))
    rows = {divmod(i, 4)[0] for i in truth.excited_cells}
    assert {table.axes[0].breakpoints[r] for r in rows} == {1500.0, 2500.0}
    # recompute from the regressor, and check the three areas (22)
    idx, w = table.regressor(signals.stack(["u1", "u2"]))
    assert sorted(set(idx[w > 0].tolist())) == paper
    areas = {tuple(sorted(row)) for row in idx.tolist()}
    assert areas == {tuple(e - 1 for e in area) for area in SIM2_AREAS_PAPER}


def test_sim2_is_noise_free_and_sim3_noisy() -> None:
    s2, t2 = skf_sim(2, seed=0)
    assert_array_equal(s2["y"], 1.0)
    assert_array_equal(t2.y_true, 1.0)
    s3, t3 = skf_sim(3, seed=0)
    assert_array_equal(s3["u1"], s2["u1"])
    assert_array_equal(s3["u2"], s2["u2"])
    noise = s3["y"] - 1.0
    assert_allclose(noise, t3.noise, atol=1e-15)
    assert np.abs(noise).max() <= 0.2
    assert np.abs(noise).max() > 0.15  # amplitude really 0.2, not smaller
    assert abs(noise.mean()) < 0.05  # zero mean (SE ≈ 0.008)
    assert abs(noise.std() - 0.2 / np.sqrt(3)) < 0.03  # uniform on [−0.2, 0.2]


@pytest.mark.parametrize("number", [1, 3])
def test_seeds_reproduce(number: int) -> None:
    a, ta = skf_sim(number, seed=7)
    b, tb = skf_sim(number, seed=7)
    c, _ = skf_sim(number, seed=8)
    for name in ("u1", "u2", "y"):
        assert a[name].tobytes() == b[name].tobytes()
    assert ta.noise.tobytes() == tb.noise.tobytes()
    random_channel = "y" if number == 3 else "u1"
    assert not np.array_equal(a[random_channel], c[random_channel])


def test_sim2_deterministic_across_seeds() -> None:
    a, _ = skf_sim(2, seed=1)
    b, _ = skf_sim(2, seed=2)
    assert a["y"].tobytes() == b["y"].tobytes()


def test_truth_to_dict_is_json() -> None:
    _, truth = skf_sim(3, seed=4)
    data = json.loads(json.dumps(truth.to_dict()))
    assert data["number"] == 3
    assert data["excited_cells"] == list(range(4, 12))
    assert Table.from_dict(data["table"]) == truth.table
    assert data["filter_settings"]["P0"] == 0.0
    assert_array_equal(data["noise"], truth.noise)


@pytest.mark.parametrize("bad", [0, 4, True, "1", 1.5])
def test_bad_number(bad: object) -> None:
    with pytest.raises(ConfigError, match="1, 2 or 3"):
        skf_sim(bad, seed=0)  # type: ignore[arg-type]


def test_bad_seed() -> None:
    with pytest.raises(ConfigError, match="seed"):
        skf_sim(1, seed=0.5)  # type: ignore[arg-type]
