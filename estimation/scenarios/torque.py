"""The torque scenarios (TQ paper): effective torque from speed, load and air flow on a
2.0 L SI engine (``torque-si``, TQ §VI) or a diesel engine on a dynamometer
(``torque-rig``, TQ §VII)."""

from __future__ import annotations

import dataclasses
from typing import Any

from estimation.registry import EstimatorKind, names
from estimation.scenarios.base import Build, Scenario, ScenarioData, scenario_metadata


def torque_scenario(name: str, description: str, channels: tuple[tuple[str, str], ...]) -> Scenario:
    rate_hz = 1000.0

    def build(b: Build) -> ScenarioData:
        from estimation.plants.torque import simulate_si_torque, simulate_torque_rig
        from estimation.plants.torque_params import DieselRigParams, SiEngineParams

        params = SiEngineParams() if name == "torque-si" else DieselRigParams()
        params = dataclasses.replace(
            params,
            speed_noise_std_rpm=params.speed_noise_std_rpm * b.noise_scale,
            load_noise_std_nm=params.load_noise_std_nm * b.noise_scale,
            air_noise_std_kg_s=params.air_noise_std_kg_s * b.noise_scale,
        )
        if name == "torque-si":
            signals, truth = simulate_si_torque(
                seed=b.seed,
                duration_s=b.duration_s,
                rate_hz=rate_hz,
                params=params,  # type: ignore[arg-type]
                transient_24s=b.transient_24s,
            )
        else:
            signals, truth = simulate_torque_rig(
                seed=b.seed,
                duration_s=b.duration_s,
                rate_hz=rate_hz,
                params=params,  # type: ignore[arg-type]
            )
        draw = b.draw(name)
        draw.relative("J_nm_s_per_rpm", truth.J_nm_s_per_rpm, "inertia", "N·m·s/rpm")
        metadata = scenario_metadata(b, draw, None)
        if name == "torque-si":
            metadata["transient_24s"] = b.transient_24s
        return ScenarioData(
            scenario=name,
            seed=b.seed,
            signals=signals,
            truth=truth.to_dict(),
            scored_series={"torque_nm": truth.torque_nm},
            metadata=metadata,
            estimator_params=draw.values(),
        )

    def configs(estimator: str, drawn: dict[str, float] | None = None) -> dict[str, Any] | None:
        from estimation.plants.torque_params import DieselRigParams, SiEngineParams

        if estimator not in names(EstimatorKind.TORQUE):
            return None
        params = SiEngineParams() if name == "torque-si" else DieselRigParams()
        J = (drawn or {}).get("J_nm_s_per_rpm", params.J_nm_s_per_rpm)
        config: dict[str, Any] = {"J_nm_s_per_rpm": J}
        if estimator == "smo":
            config["lambda1"] = 150.0 if name == "torque-si" else 350.0  # TQ §VI, §VII
        return config

    return Scenario(
        name=name,
        description=description,
        rate_hz=rate_hz,
        duration_s=30.0,
        channels=channels,
        suggested=names(EstimatorKind.TORQUE),
        builder=build,
        configs=configs,
        options=("transient_24s",) if name == "torque-si" else (),
    )
