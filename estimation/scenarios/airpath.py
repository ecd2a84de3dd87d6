"""The MAF scenarios (LPV and EKF papers): MAF-sensor error maps on the diesel air path with
EGR and VGT, on the WHTC or the FTP-75 (``maf-whtc``, ``maf-ftp75``: an additive 2-D error
map; ``maf-1d-whtc``: a relative 1-D one), with the sensors' logging, the estimator-side
air-path constants drawn under mismatch and the observers' flow model identified on the
other cycle."""

from __future__ import annotations

import dataclasses
from typing import Any

from estimation.scenarios.base import Build, Scenario, ScenarioData, scenario_metadata

_LPV_FULL_LOAD_RPM = (800.0, 1000.0, 1250.0, 1500.0, 1750.0, 2500.0, 3000.0, 3250.0, 3500.0)
_LPV_FULL_LOAD_NM = (118.0, 162.0, 221.0, 263.0, 280.0, 280.0, 255.0, 126.0, 0.0)


# The air-path scenarios' logging (every level but "none"): the ECU reads every sensor in its
# 10 ms task and logs the mean of the ten readings of each 100 ms sample
# (NoiseSpec.averaged_readings): σ/√10 per logged sample, for every air-path scenario alike.
# ``averaging=1`` logs single readings. At "none" the pre-issue-17 logging is kept (ten
# readings on the 2-D scenarios, single readings on maf-1d-whtc) so those runs reproduce.
_AIRPATH_READINGS = 10
_AIRPATH_LOGGING = "mean of 10 readings (10 ms) per 100 ms sample"

# Estimator-side air-path constants drawn under mismatch (estimation.observers.airpath_model).
_AIRPATH_DRAWN: tuple[tuple[str, str, str], ...] = (
    ("V_im", "volume", "m³"),
    ("V_em", "volume", "m³"),
    ("c_vol3", "efficiency", "-"),
    ("eta_cmax", "efficiency", "-"),
    ("eta_tmmax", "efficiency", "-"),
    ("A_egrmax", "flow_area", "m²"),
    ("A_vgtmax", "flow_area", "m²"),
    ("J_t", "inertia", "kg m²"),
)
# The observers' flow model is then identified (estimation.observers.airpath_identify) on the
# first 600 s of the other cycle, driven with its own noise (seed + _ID_SEED_OFFSET) and
# logged with a reference flow meter in place of the MAF under test.
_ID_CYCLE = {"whtc": "ftp75", "ftp75": "whtc"}
_AIRPATH_MODEL = tuple(p for p, _, _ in _AIRPATH_DRAWN)
_ID_DURATION_S = 600.0
_ID_SEED_OFFSET = 500_000
# The EKFs' sensor σ, drawn around the plant's logged σ (single reading / √averaging).
_AIRPATH_SIGMAS: tuple[tuple[str, str, str], ...] = (
    ("sigma_maf_rel", "maf_rel", "-"),
    ("sigma_p_im", "p_im_pa", "Pa"),
    ("sigma_p_em", "p_em_pa", "Pa"),
    ("sigma_omega_t_rel", "omega_t_rel", "-"),
)


def _airpath_points(cycle: str, rate_hz: float) -> Any:
    from estimation.cycles import load_cycle
    from estimation.plants.engine import DieselEngine
    from estimation.plants.vehicle import operating_points

    engine = None
    if cycle == "whtc":
        engine = DieselEngine(
            rated_speed_rpm=3000.0,
            full_load_speed_rpm=_LPV_FULL_LOAD_RPM,
            full_load_torque_nm=_LPV_FULL_LOAD_NM,
        )
    return operating_points(load_cycle(cycle), rate_hz=rate_hz, engine=engine)


def _identified_model(
    cycle: str, seed: int, noise: Any, drawn: dict[str, float], rate_hz: float
) -> tuple[dict[str, float], dict[str, Any]]:
    """The drawn air-path model with its flow terms identified on the identification segment
    (``_ID_CYCLE``); returns the model's values and a report for the metadata."""
    from estimation.observers.airpath_identify import DEFAULT_FIT, identify_flow_model
    from estimation.observers.airpath_model import AirpathModelConfig
    from estimation.plants.airpath import simulate_airpath
    from estimation.plants.airpath_params import AirpathParams
    from estimation.plants.airpath_sensors import MafErrorSpec

    id_cycle = _ID_CYCLE[cycle]
    points = _airpath_points(id_cycle, rate_hz)
    stop = int(_ID_DURATION_S * rate_hz) + 1
    signals, _ = simulate_airpath(
        points.time_s[:stop],
        points.fuel_mg_per_cycle[:stop],
        points.speed_rpm[:stop],
        seed=seed + _ID_SEED_OFFSET,
        maf_error=MafErrorSpec.none(),
        noise=noise,
        rate_hz=rate_hz,
        reuse_plant_run=True,
    )
    model, report = identify_flow_model(signals, signals["maf_kg_s"], AirpathModelConfig(**drawn))
    plant = AirpathParams.scaled()
    report |= {
        "segment": f"{id_cycle} 0–{_ID_DURATION_S:g} s, reference flow meter",
        "plant": {name: float(getattr(plant, name)) for name in DEFAULT_FIT},
        "drawn": {name: float(drawn[name]) for name in DEFAULT_FIT},
    }
    return model.model_dump(), report


def maf_scenario(name: str, cycle: str, kind: str, description: str, duration_s: float) -> Scenario:
    rate_hz = 10.0

    def build(b: Build) -> ScenarioData:
        from estimation.plants.airpath import simulate_airpath
        from estimation.plants.airpath_sensors import MafErrorSpec, NoiseSpec
        from estimation.truth_maps import MAF_ERROR_2D, MAF_RELATIVE_1D

        points = _airpath_points(cycle, rate_hz)
        stop = points.time_s.size if b.duration_s is None else int(b.duration_s * rate_hz) + 1
        spec = MafErrorSpec.additive_2d() if kind == "2d" else MafErrorSpec.relative_1d()
        truth_map = MAF_ERROR_2D if kind == "2d" else MAF_RELATIVE_1D
        if b.off_grid:
            spec = dataclasses.replace(spec, function=truth_map)
        averaging = b.averaging
        if averaging is None:
            averaging = _AIRPATH_READINGS if b.off_grid or kind == "2d" else 1
        stated = NoiseSpec(averaged_readings=averaging)
        noise = stated.scaled(b.noise_scale)
        signals, truth = simulate_airpath(
            points.time_s[:stop],
            points.fuel_mg_per_cycle[:stop],
            points.speed_rpm[:stop],
            seed=b.seed,
            maf_error=spec,
            noise=noise,
            rate_hz=rate_hz,
            reuse_plant_run=True,
        )
        draw = b.draw(name)
        for param, cls, unit in _AIRPATH_DRAWN:
            draw.relative(param, getattr(truth.params, param), cls, unit)  # type: ignore[arg-type]
        for param, plant_name, unit in _AIRPATH_SIGMAS:
            # around the stated logging's σ: the estimators are not told of noise_scale
            logged = getattr(stated, plant_name) * stated.logged_scale()
            draw.relative(param, logged, "noise_sigma", unit)
        metadata = scenario_metadata(b, draw, averaging)
        estimator_params = draw.values()
        if b.off_grid:
            drawn_model = {p: estimator_params[p] for p, _, _ in _AIRPATH_DRAWN}
            # the identification log is logged like the scenario's, noise_scale included
            model, metadata["identification"] = _identified_model(
                cycle, b.seed, noise, drawn_model, rate_hz
            )
            estimator_params |= {p: model[p] for p in _AIRPATH_MODEL}
        true_map = spec.table
        assert true_map is not None
        if kind == "2d":
            inputs: tuple[str, ...] = ("fuel_mg_per_cycle", "speed_rpm")
            points_true = signals.stack(list(inputs))
        else:
            inputs = ("maf_kg_s",)
            points_true = truth["w_c_kg_s"][:, None]
        return ScenarioData(
            scenario=name,
            seed=b.seed,
            signals=signals,
            truth=truth.to_dict(),
            true_map=true_map,
            map_inputs=inputs,
            map_output=None,
            map_points=points_true,
            scored_series={"w_c_kg_s": truth["w_c_kg_s"]},
            true_along=truth_map(points_true) if b.off_grid else None,
            metadata=metadata,
            estimator_params=estimator_params,
        )

    suggested = ("lpv",) if kind == "2d" else ("ekf-map", "ekf-aug", "ekf-def")
    return Scenario(
        name=name,
        description=description,
        rate_hz=rate_hz,
        duration_s=duration_s,
        channels=(
            ("fuel_mg_per_cycle", "mg/cycle"),
            ("speed_rpm", "rpm"),
            ("p_im_pa", "Pa"),
            ("p_em_pa", "Pa"),
            ("omega_t_rad_s", "rad/s"),
            ("maf_kg_s", "kg/s"),
            ("u_egr_pct", "%"),
            ("u_vgt_pct", "%"),
        ),
        suggested=suggested,
        builder=build,
        configs=lambda estimator, drawn=None: _maf_config(estimator, kind, suggested, drawn or {}),
        logging=_AIRPATH_LOGGING,
        averaging=_AIRPATH_READINGS,
    )


def _maf_config(
    estimator: str, kind: str, suggested: tuple[str, ...], drawn: dict[str, float]
) -> dict[str, Any] | None:
    """Configs on the MAF scenarios: the EKF observers (EKF §5.1) run on all of them, Map only
    where the true error is its 1-D relative map (on the scenario's own W grid). With drawn
    constants (mismatch), each observer gets its drawn air-path model, the LPV observer
    computes ρ with it, and the EKFs get their drawn sensor σ."""
    model = {p: drawn[p] for p in _AIRPATH_MODEL if p in drawn}
    sigmas = {p: drawn[p] for p, _, _ in _AIRPATH_SIGMAS if p in drawn}
    mismatched: dict[str, Any] = {"model": model} if model else {}
    if estimator in ("ekf-def", "ekf-aug"):
        return mismatched | sigmas
    if estimator == "ekf-map":
        if kind != "1d":
            return None
        from estimation.plants.airpath_sensors import MafErrorSpec

        table = MafErrorSpec.relative_1d().table
        assert table is not None
        return {"breakpoints": [float(b) for b in table.axes[0].breakpoints]} | mismatched | sigmas
    if estimator not in suggested:
        return None
    return mismatched | ({"rho_source": "model"} if model else {})
