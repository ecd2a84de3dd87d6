"""Model mismatch between plant and estimators (estimation.mismatch, docs/fidelity.md)."""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from estimation.errors import ConfigError
from estimation.mismatch import RANGES, MismatchDraw
from estimation.observers.airpath_model import AirpathModelConfig
from estimation.observers.ekf_config import EkfAugConfig
from estimation.observers.lpv_config import LpvConfig
from estimation.plants.airpath_params import AirpathParams
from estimation.plants.airpath_sensors import NoiseSpec
from estimation.plants.nox import DEFAULT_NOX_PARAMS
from estimation.plants.torque_params import DieselRigParams, SiEngineParams
from estimation.registry import get_spec
from estimation.scenarios import ScenarioData, get_scenario
from estimation.torque.config import DEFAULT_J_NM_S_PER_RPM, UioConfig
from estimation.truth_maps import MAF_ERROR_2D, NOX_BASE

ROOT = Path(__file__).resolve().parents[2]


@cache
def built(name: str, level: str, seed: int = 100, duration_s: float = 30.0) -> ScenarioData:
    return get_scenario(name).build(seed=seed, duration_s=duration_s, mismatch=level)


def test_estimators_import_no_plant_module() -> None:
    """No estimator reads the simulator's parameters: nothing under estimation/observers,
    estimation/torque or estimation/filters imports estimation.plants, at any depth of the
    module (function-local imports included)."""
    offenders = []
    for folder in ("observers", "torque", "filters"):
        for path in sorted((ROOT / "estimation" / folder).glob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and node.module:
                    modules = [node.module]
                elif isinstance(node, ast.Import):
                    modules = [a.name for a in node.names]
                else:
                    continue
                offenders += [
                    f"{path.name}: {m}" for m in modules if m.startswith("estimation.plants")
                ]
    assert offenders == []


def test_documented_defaults_are_the_plants_nominal_values() -> None:
    """The estimators' own defaults equal the simulator's nominal values, which is what makes
    ``mismatch="none"`` the perfect-model setting."""
    assert_array_equal(AirpathModelConfig().vector(), AirpathParams.scaled().to_vector())
    assert AirpathModelConfig().a1() == AirpathParams.scaled().a1
    assert SiEngineParams().J_nm_s_per_rpm == DEFAULT_J_NM_S_PER_RPM
    noise = NoiseSpec()
    ekf = EkfAugConfig()
    assert (ekf.sigma_maf_rel, ekf.sigma_p_im, ekf.sigma_p_em, ekf.sigma_omega_t_rel) == (
        noise.maf_rel,
        noise.p_im_pa,
        noise.p_em_pa,
        noise.omega_t_rel,
    )
    sensor = get_scenario("nox-nedc").default_config("skf")["sensor"]
    assert (sensor["lag"], sensor["delay_s"]) == (
        DEFAULT_NOX_PARAMS.lag,
        DEFAULT_NOX_PARAMS.delay_s,
    )


def test_none_hands_the_estimators_the_plants_values() -> None:
    for name in ("maf-whtc", "nox-nedc", "torque-rig"):
        data = built(name, "none")
        assert data.estimator_params == {}
        assert data.metadata["truth"] == "table"
        assert data.true_along is None
        assert data.metadata["parameters"]
        assert all(r["estimator"] == r["plant"] for r in data.metadata["parameters"])
    rig = get_scenario("torque-rig")
    cfg = rig.default_config("uio", data=built("torque-rig", "none"))
    assert cfg["J_nm_s_per_rpm"] == DieselRigParams().J_nm_s_per_rpm


@pytest.mark.parametrize("level", ["nominal", "severe"])
def test_nominal_estimator_configs_differ_from_the_plant(level: str) -> None:
    """Under nominal (and severe) every estimator-side constant differs from the plant's and
    is within its documented range, and it is what the estimator's config carries."""
    scale = 2.0 if level == "severe" else 1.0
    classes = {"V_im": "volume", "c_vol3": "efficiency", "A_vgtmax": "flow_area", "J_t": "inertia"}
    for name in ("maf-whtc", "maf-1d-whtc", "nox-nedc", "torque-si", "torque-rig"):
        data = built(name, level)
        records = {r["name"]: r for r in data.metadata["parameters"]}
        for key, r in records.items():
            if r["unit"] == "samples":
                assert abs(r["estimator"] - r["plant"]) <= scale * RANGES["delay"], r
                continue
            assert r["estimator"] != r["plant"], r
            if key in classes:
                bound = scale * RANGES[classes[key]]
                assert abs(r["estimator"] / r["plant"] - 1.0) <= bound, r
    whtc = built("maf-whtc", level)
    lpv = LpvConfig(**get_scenario("maf-whtc").default_config("lpv", data=whtc))
    plant = AirpathParams.scaled()
    assert lpv.rho_source == "model"
    for key in ("V_im", "V_em", "eta_tmmax", "A_vgtmax", "J_t", "c_vol3", "A_egrmax"):
        assert getattr(lpv.model, key) == whtc.estimator_params[key]
        assert getattr(lpv.model, key) != getattr(plant, key), key
    assert lpv.model.a1() != plant.a1
    ekf_cfg = get_scenario("maf-1d-whtc").default_config(
        "ekf-aug", data=built("maf-1d-whtc", level)
    )
    ekf = EkfAugConfig(**ekf_cfg)
    assert ekf.model.V_em != plant.V_em
    assert ekf.sigma_p_im != NoiseSpec().p_im_pa / np.sqrt(10)
    si = built("torque-si", level)
    uio = UioConfig(**get_scenario("torque-si").default_config("uio", data=si))
    assert uio.J_nm_s_per_rpm == si.estimator_params["J_nm_s_per_rpm"]
    assert uio.J_nm_s_per_rpm != SiEngineParams().J_nm_s_per_rpm
    skf = get_scenario("nox-nedc").default_config("skf", data=built("nox-nedc", level))
    assert skf["sensor"]["lag"] != DEFAULT_NOX_PARAMS.lag
    assert skf["sigma_v"] != DEFAULT_NOX_PARAMS.noise_std_ppm


def test_draw_is_seeded_by_the_scenario_seed_and_severe_doubles_the_offsets() -> None:
    def offsets(level: str, seed: int) -> np.ndarray:
        d = MismatchDraw("maf-whtc", seed, level)  # type: ignore[arg-type]
        values = [d.relative(f"p{i}", 1.0, "efficiency") for i in range(5)]
        return np.array(values) - 1.0

    nominal = offsets("nominal", 100)
    assert_array_equal(nominal, offsets("nominal", 100))
    assert not np.array_equal(nominal, offsets("nominal", 101))
    np.testing.assert_allclose(offsets("severe", 100), 2.0 * nominal, rtol=1e-12)
    assert np.all(np.abs(nominal) <= RANGES["efficiency"])
    assert_array_equal(offsets("none", 100), 0.0)
    delays = [MismatchDraw("x", s, "nominal").samples("d", 38) for s in range(60)]
    assert set(delays) == {37, 38, 39}


def test_truth_is_a_smooth_function_off_the_grid_under_nominal() -> None:
    nox = built("nox-nedc", "nominal")
    truth = np.array(nox.truth["nox_true_ppm"])
    points = nox.scoring_points()
    age = (nox.signals.time - nox.signals.time[0]) / 3600.0
    p = DEFAULT_NOX_PARAMS
    expected = (1 + p.drift_gain_per_h * age) * NOX_BASE(points) + p.drift_offset_ppm_per_h * age
    np.testing.assert_allclose(truth, expected, rtol=1e-12)
    on_grid = np.array(built("nox-nedc", "none").truth["nox_true_ppm"])
    assert np.max(np.abs(truth - on_grid)) > 1.0  # ppm: the table is not the truth between nodes
    maf = built("maf-whtc", "nominal")
    assert maf.metadata["truth"] == "function"
    assert maf.true_along is not None
    np.testing.assert_allclose(maf.true_along, MAF_ERROR_2D(maf.scoring_points()))
    injected = np.array(maf.truth["maf_error_kg_s"])
    np.testing.assert_allclose(injected, MAF_ERROR_2D(maf.scoring_points()), atol=1e-15)


def test_averaging_is_the_scenarios_logging_and_can_be_single_readings() -> None:
    sc = get_scenario("maf-1d-whtc")
    assert sc.averaging == 10
    assert "10 readings" in sc.catalog_entry()["logging"]
    assert built("maf-1d-whtc", "nominal").metadata["averaging"] == 10
    assert built("maf-1d-whtc", "none").metadata["averaging"] == 1  # as before issue 17
    single = sc.build(seed=100, duration_s=30.0, averaging=1)
    assert single.metadata["averaging"] == 1
    p_single = single.signals["p_im_pa"] - np.array(single.truth["channels"]["p_im_pa"])
    mean10 = built("maf-1d-whtc", "nominal")
    p_mean = mean10.signals["p_im_pa"] - np.array(mean10.truth["channels"]["p_im_pa"])
    assert np.std(p_single) > 2.5 * np.std(p_mean)
    with pytest.raises(ConfigError, match="averaging applies to the air-path scenarios"):
        get_scenario("torque-si").build(seed=0, duration_s=1.0, averaging=1)
    with pytest.raises(ConfigError, match="averaging must be in"):
        sc.build(seed=0, duration_s=1.0, averaging=0)
    with pytest.raises(ConfigError, match="mismatch must be one of none, nominal, severe"):
        sc.build(seed=0, duration_s=1.0, mismatch="mild")  # type: ignore[arg-type]


def test_flow_model_is_identified_on_its_own_segment() -> None:
    """The drawn volumetric-efficiency offset and EGR area are re-identified on the other
    cycle's first 600 s (with a reference flow meter): within 0.5 % and 2 % of the plant."""
    for level in ("nominal", "severe"):
        ident = built("maf-whtc", level).metadata["identification"]
        assert ident["segment"].startswith("ftp75")
        for key, tol in (("c_vol3", 0.005), ("A_egrmax", 0.02)):
            plant, drawn, fitted = ident["plant"][key], ident["drawn"][key], ident["values"][key]
            assert abs(fitted / plant - 1.0) <= tol, (key, ident)
            assert abs(fitted - plant) < abs(drawn - plant), (key, ident)


def test_lpv_model_rho_with_the_plants_values_is_the_logged_rho() -> None:
    """ρ computed by the observer's own model reproduces the logged ρ channels when the model
    has the plant's values, so mismatch=none runs are unchanged."""
    data = built("maf-whtc", "none", duration_s=120.0)
    spec = get_spec("lpv")
    channels = spec.build({}).fit(data.signals).table
    model = spec.build({"rho_source": "model"}).fit(data.signals).table
    assert_array_equal(channels.values, model.values)
