"""The NOx scenarios (SKF paper §6): an engine-out NOx map drifting slowly, seen through a
delayed, lagged sensor, on a sportive mountain drive (``nox-sdmp``) or the NEDC
(``nox-nedc``)."""

from __future__ import annotations

import dataclasses
from typing import Any

from estimation.scenarios.base import (
    Build,
    Scenario,
    ScenarioData,
    scenario_metadata,
    table_filter_config,
)


def nox_scenario(name: str, cycle: str, description: str, duration_s: float) -> Scenario:
    rate_hz = 50.0

    def build(b: Build) -> ScenarioData:
        from estimation.cycles import load_cycle, make_sdmp
        from estimation.plants.nox import DEFAULT_NOX_PARAMS, simulate_nox
        from estimation.plants.vehicle import operating_points
        from estimation.signals import delay_samples
        from estimation.truth_maps import NOX_BASE

        drive = make_sdmp(seed=b.seed) if cycle == "sdmp" else load_cycle(cycle)
        points = operating_points(drive, rate_hz=rate_hz)
        stop = points.time_s.size if b.duration_s is None else int(b.duration_s * rate_hz) + 1
        plant = DEFAULT_NOX_PARAMS
        signals, truth = simulate_nox(
            points.time_s[:stop],
            points.speed_rpm[:stop],
            points.fuel_mg_per_cycle[:stop],
            seed=b.seed,
            params=dataclasses.replace(plant, noise_std_ppm=plant.noise_std_ppm * b.noise_scale),
            base_function=NOX_BASE if b.off_grid else None,
        )
        draw = b.draw(name)
        draw.time_constant_pole("sensor_lag", plant.lag, 1.0 / rate_hz)
        draw.samples("sensor_delay_samples", delay_samples(plant.delay_s, 1.0 / rate_hz))
        draw.relative("sigma_v_ppm", plant.noise_std_ppm, "noise_sigma", "ppm")
        data = ScenarioData(
            scenario=name,
            seed=b.seed,
            signals=signals,
            truth=truth.to_dict(),
            true_map=truth.final_map,
            map_inputs=("speed_rpm", "fuel_mg_per_stroke"),
            map_output="nox_ppm",
            metadata=scenario_metadata(b, draw, None),
            estimator_params=draw.values(),
        )
        if not b.off_grid:
            return data
        age = truth.age_h_at(float(truth.time_s[-1]))
        base = NOX_BASE(data.scoring_points())
        along = (1.0 + plant.drift_gain_per_h * age) * base + plant.drift_offset_ppm_per_h * age
        return dataclasses.replace(data, true_along=along)

    def configs(estimator: str, drawn: dict[str, float] | None = None) -> dict[str, Any] | None:
        from estimation.plants.nox import nox_base_map

        # SKF (34): σv = 25, σw = 15, σf = 50 ppm, a = 0.96, τ = 0.75 s at 50 Hz; T_NOx,0 = 0.
        # Under mismatch the sensor's pole, delay and σv are the realisation's drawn values.
        drawn = drawn or {}
        delay = drawn.get("sensor_delay_samples")
        sensor = {
            "lag": drawn.get("sensor_lag", 0.96),
            "delay_s": 0.75 if delay is None else delay / rate_hz,
            "sigma_f": 50.0,
        }
        config = table_filter_config(
            estimator,
            nox_base_map(),
            "nox_ppm",
            output_unit="ppm",
            sigma_w=15.0,
            sigma_v=drawn.get("sigma_v_ppm", 25.0),
            p0=1.0e4,
            sensor=sensor,
        )
        if estimator == "rls" and config is not None:
            # The papers give no RLS calibration. RLS with forgetting winds up where the
            # regressor stays constant: in the directions of the active block the data do not
            # see, P grows as λ^-k. On the NEDC at 50 Hz 69 % of the samples sit on an exactly
            # constant regressor (idle, cruises of up to 3451 samples), so with λ = 0.995
            # P reached P0·λ^-3451 ≈ 3e10 and noise drove cells to ±25 000 ppm (map error
            # 1763–6855 %, seeds 0–2). Hence a 20 s memory, 1/(1−λ) = 1000 samples, and the
            # covariance limit at P0 (EKF §3.1, docs/algorithms.md §2.5) so no dwell can wind it up;
            # P0 = 1000 is normalised by σv², a prior σ of √1000·25 ≈ 790 ppm.
            # See tests/estimation/test_rls_windup.py.
            config |= {"forgetting": 0.999, "p0": 1000.0, "limit": "p0"}
        return config

    return Scenario(
        name=name,
        description=description,
        rate_hz=rate_hz,
        duration_s=duration_s,
        channels=(("speed_rpm", "rpm"), ("fuel_mg_per_stroke", "mg/stroke"), ("nox_ppm", "ppm")),
        suggested=("skf", "kf", "sskf"),
        builder=build,
        configs=configs,
    )
