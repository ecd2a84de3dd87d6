"""``noise_scale`` of a scenario build (estimation/scenarios/): it multiplies every sensor
noise σ of the plant's logging and leaves the estimators' σ settings as configured."""

from __future__ import annotations

import numpy as np
import pytest

from estimation.errors import ConfigError
from estimation.scenarios import ScenarioData, get_scenario

# scenario, build arguments, [(measured channel, its noise-free value from the data)]
CASES = [
    ("skf-sim3", {}, ["y"]),
    ("nox-nedc", {"duration_s": 60.0}, ["nox_ppm"]),
    ("maf-1d-whtc", {"duration_s": 40.0, "mismatch": "none"}, ["maf_kg_s", "p_im_pa"]),
    ("torque-si", {"duration_s": 1.0}, ["speed_rpm", "load_torque_nm"]),
    ("torque-rig", {"duration_s": 1.0}, ["speed_rpm", "load_torque_nm"]),
]


def noise_free(data: ScenarioData, channel: str) -> np.ndarray:
    """The channel as the plant's logging would record it without sensor noise."""
    truth = data.truth
    if data.scenario.startswith("skf-sim"):
        return np.asarray(truth["y_true"])
    if data.scenario.startswith("nox"):
        return np.asarray(truth["nox_sensor_noise_free_ppm"])
    if data.scenario.startswith("maf"):
        ch = truth["channels"]
        if channel == "maf_kg_s":  # the MAF error is the map under test, not noise
            return np.asarray(ch["w_c_kg_s"]) + np.asarray(truth["maf_error_kg_s"])
        return np.asarray(ch[channel])
    return np.asarray(truth[channel])


@pytest.mark.parametrize(("name", "kwargs", "channels"), CASES, ids=[c[0] for c in CASES])
def test_zero_gives_the_noise_free_log_and_two_doubles_the_residual_sigma(
    name: str, kwargs: dict, channels: list[str]
) -> None:
    scenario = get_scenario(name)
    seed = 7
    plain = scenario.build(seed=seed, **kwargs)
    quiet = scenario.build(seed=seed, noise_scale=0.0, **kwargs)
    loud = scenario.build(seed=seed, noise_scale=2.0, **kwargs)
    assert quiet.metadata["noise_scale"] == 0.0
    assert loud.metadata["noise_scale"] == 2.0
    assert plain.metadata["noise_scale"] == 1.0
    for channel in channels:
        clean = noise_free(quiet, channel)
        np.testing.assert_allclose(quiet.signals[channel], clean, rtol=1e-12, atol=0.0)
        # the truth does not depend on the noise level
        np.testing.assert_allclose(noise_free(loud, channel), clean, rtol=1e-12, atol=0.0)
        sigma1 = np.std(plain.signals[channel] - clean)
        sigma2 = np.std(loud.signals[channel] - clean)
        assert sigma1 > 0.0
        assert sigma2 / sigma1 == pytest.approx(2.0, rel=0.02)
    # the estimators are not told: their drawn σ and model constants are the same
    assert loud.estimator_params == plain.estimator_params
    for estimator in scenario.suggested[:1]:
        assert scenario.default_config(estimator, data=loud) == scenario.default_config(
            estimator, data=plain
        )


def test_nominal_airpath_estimator_sigmas_stay_as_drawn() -> None:
    scenario = get_scenario("maf-1d-whtc")
    plain = scenario.build(seed=3, duration_s=20.0)
    loud = scenario.build(seed=3, duration_s=20.0, noise_scale=2.0)
    assert loud.mismatch == "nominal"
    for key in ("sigma_maf_rel", "sigma_p_im"):
        assert loud.estimator_params[key] == plain.estimator_params[key]
    assert loud.truth["noise"]["maf_rel"] == pytest.approx(2.0 * plain.truth["noise"]["maf_rel"])


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), 101.0, True, "2"])
def test_out_of_range_noise_scale_is_refused(bad: object) -> None:
    with pytest.raises(ConfigError, match="noise_scale"):
        get_scenario("skf-sim3").build(noise_scale=bad)  # type: ignore[arg-type]


def test_transient_24s_is_a_torque_si_option_only() -> None:
    with pytest.raises(ConfigError, match="transient_24s"):
        get_scenario("torque-rig").build(duration_s=1.0, transient_24s=True)
    assert "transient_24s" in get_scenario("torque-si").catalog_entry()["options"]
