"""The air-path headline claims on held-out seeds under ``mismatch="nominal"`` (issue 17).

Nothing was tuned on seeds 100–109. What holds is asserted; what does not is asserted in the
form that does hold, with the figures, and explained in docs/fidelity.md#held-out (the table
there is ``scripts/fidelity.py``'s). The torque claims are in test_torque_estimators.py, the
NOx held-out prediction in test_holdout.py.
"""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pytest

from estimation.metrics import map_metrics
from estimation.registry import get_spec
from estimation.scenarios import ScenarioData, get_scenario

HELD_OUT = tuple(range(100, 110))
PAPER = {"maf-whtc": 0.1041, "maf-ftp75": 0.0528}  # LPV §4: ETC part 1, FTP-75 cold start
SEGMENT_S = {"maf-whtc": 600.0, "maf-ftp75": 505.0}

pytestmark = pytest.mark.slow


@cache
def realisation(name: str, seed: int, averaging: int | None = None) -> ScenarioData:
    return get_scenario(name).build(seed=seed, mismatch="nominal", averaging=averaging)


def head(data: ScenarioData, seconds: float) -> ScenarioData:
    """The first ``seconds`` of a realisation (signals, scoring points, truth along them)."""
    t = data.signals.time
    stop = int(np.searchsorted(t, t[0] + seconds, side="right"))
    assert data.map_points is not None
    assert data.true_along is not None
    return dataclasses.replace(
        data,
        signals=data.signals.slice(0, stop),
        map_points=data.map_points[:stop],
        true_along=data.true_along[:stop],
    )


@cache
def lpv_mre(name: str, seed: int, part: str, variant: str = "identified") -> float:
    """LPV mean relative error (docs/algorithms.md §3, against the off-grid truth) over the
    whole cycle or the paper's segment; ``variant``: the identified model (default), the
    drawn model before identification, or single sensor readings."""
    data = realisation(name, seed, 1 if variant == "single" else None)
    config = get_scenario(name).default_config("lpv", data=data)
    if variant == "drawn":
        drawn = data.metadata["identification"]["drawn"]
        config = config | {"model": config["model"] | drawn}
    if part == "segment":
        data = head(data, SEGMENT_S[name])
    snap = get_spec("lpv").build(config).fit(data.signals)
    assert data.true_map is not None
    return map_metrics(
        snap.table, data.true_map, data.scoring_points(), truth_along=data.true_along
    )["mean_relative_error"]


@pytest.mark.parametrize("seed", HELD_OUT)
def test_lpv_whole_whtc_is_within_the_etc_figure(seed: int) -> None:
    """Whole WHTC, nominal: 5.0–8.6 % on seeds 100–109, within the paper's 10.41 %."""
    assert lpv_mre("maf-whtc", seed, "full") <= PAPER["maf-whtc"]


def test_lpv_whtc_first_600_s_meets_the_etc_figure_on_average() -> None:
    """The paper's ETC part 1 stand-in (WHTC 0–600 s): the seed mean, 9.0 %, is within
    10.41 %; single seeds are not all (7.3–10.7 %; docs/fidelity.md#held-out)."""
    mres = [lpv_mre("maf-whtc", seed, "segment") for seed in HELD_OUT]
    assert float(np.mean(mres)) <= PAPER["maf-whtc"], mres


@pytest.mark.parametrize("seed", HELD_OUT)
def test_identifying_the_flow_model_is_what_makes_the_whtc_map_usable(seed: int) -> None:
    """With the drawn model (±5 % η_vol offset and EGR area) the map error over WHTC 0–600 s
    is 37–295 %; identified on its own segment it is 7.3–10.7 %, at least 4 times smaller on
    every seed (docs/fidelity.md#held-out)."""
    assert lpv_mre("maf-whtc", seed, "segment") < lpv_mre("maf-whtc", seed, "segment", "drawn") / 3


def test_identification_helps_on_the_ftp75_but_the_map_still_misses_the_paper() -> None:
    """FTP-75 0–505 s: identification cuts the seed-mean map error from 142 % to 37 %, but
    not on every seed (seed 105's draw happened to cancel: 36 % either way), and 37 % is far
    from the paper's 5.28 %: the map there averages 0.67 g/s, so 0.1 % of flow-model error
    is 10 % of map (docs/fidelity.md#held-out)."""
    identified = [lpv_mre("maf-ftp75", seed, "segment") for seed in HELD_OUT]
    drawn = [lpv_mre("maf-ftp75", seed, "segment", "drawn") for seed in HELD_OUT]
    assert np.mean(identified) < np.mean(drawn) / 3.0, (identified, drawn)
    assert max(identified) < 0.45, identified


@pytest.mark.parametrize("name", ["maf-whtc", "maf-ftp75"])
@pytest.mark.parametrize("seed", HELD_OUT)
def test_single_sensor_readings_are_worse_than_the_averaged_logging(name: str, seed: int) -> None:
    """The same runs with single 10 ms readings instead of the mean of ten: the map error
    rises on both segments, every seed (WHTC 26–34 % against 7–11 %; FTP-75 41–60 % against
    35–40 %)."""
    assert lpv_mre(name, seed, "segment", "single") > lpv_mre(name, seed, "segment")


@cache
def ekf_rmse(seed: int) -> dict[str, float]:
    """RMSE [kg/s] of each EKF variant's W_c(x̂) against the true flow on maf-1d-whtc."""
    sc = get_scenario("maf-1d-whtc")
    data = realisation("maf-1d-whtc", seed)
    truth = data.scored_series["w_c_kg_s"]
    out = {}
    for name in ("ekf-def", "ekf-aug", "ekf-map"):
        snap = get_spec(name).build(sc.default_config(name, data=data)).fit(data.signals)
        out[name] = float(np.sqrt(np.mean((snap.outputs["w_c_kg_s"] - truth) ** 2)))
    return out


@pytest.mark.parametrize("seed", HELD_OUT)
def test_ekf_aug_and_map_agree_but_def_is_no_longer_twice_as_bad(seed: int) -> None:
    """EKF Table 1's pattern under nominal mismatch: Aug and Map within 30 % of each other
    (holds: Map/Aug 0.96–0.99), Def more than twice their error (does not, on any held-out
    seed: Def is 0.93–1.68 times the better of the two; all three 0.5–5.4 g/s against
    0.45 / 0.10 / 0.10 g/s with the perfect model). W_c(x̂) is off because of the
    turbine-side constants (η_tm, A_vgt), which MAF-only feedback cannot tell from a sensor
    error (docs/fidelity.md#held-out)."""
    r = ekf_rmse(seed)
    assert 1 / 1.3 < r["ekf-map"] / r["ekf-aug"] < 1.3, r
    assert r["ekf-def"] < 2.0 * min(r["ekf-aug"], r["ekf-map"]), r
