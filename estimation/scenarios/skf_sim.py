"""The SKF paper's three synthetic problems (SKF §5): a constant map y = 1 on a 4×4 grid,
seen through uniform, poorly exciting or noisy inputs."""

from __future__ import annotations

from typing import Any

from estimation.scenarios.base import (
    Build,
    Scenario,
    ScenarioData,
    scenario_metadata,
    table_filter_config,
    truncate,
)


def skf_sim_scenario(number: int) -> Scenario:
    from estimation.plants.synthetic import skf_sim, skf_sim_table

    def build(b: Build) -> ScenarioData:
        # The SKF paper's synthetic problems: the truth y = 1 is constant (any grid represents
        # it) and the filters have no model constants, only the paper's σ; every level is the
        # paper's problem (docs/fidelity.md).
        signals, truth = skf_sim(
            number,  # type: ignore[arg-type]
            seed=b.seed,
            noise_scale=b.noise_scale,
        )
        return ScenarioData(
            scenario=f"skf-sim{number}",
            seed=b.seed,
            signals=truncate(signals, b.duration_s),
            truth=truth.to_dict(),
            true_map=truth.table,
            map_inputs=("u1", "u2"),
            map_output="y",
            metadata=scenario_metadata(b, None, None),
        )

    def configs(estimator: str, drawn: dict[str, float] | None = None) -> dict[str, Any] | None:
        # SKF §5: θ0 = 0, P0 = 0, σv² = σw² = 1.
        return table_filter_config(
            estimator, skf_sim_table(), "y", sigma_w=1.0, sigma_v=1.0, p0=0.0
        )

    descriptions = {
        1: "1400 inputs uniform over the 4×4 grid, y = 1 (SKF §5.1): every filter converges.",
        2: "u1 = 2000 rpm, u2 swept 0→60→0 in 200 steps, y = 1 (SKF §5.2): poor excitation; "
        "KF and SKF converge on the 8 excited cells, SSKF does not.",
        3: "As skf-sim2 with uniform noise of amplitude 0.2 on y (SKF §5.3).",
    }
    return Scenario(
        name=f"skf-sim{number}",
        description=descriptions[number],
        rate_hz=1.0,
        duration_s=1400.0 if number == 1 else 200.0,
        channels=(("u1", "rpm"), ("u2", "mg/stroke"), ("y", "-")),
        suggested=("kf", "skf", "sskf"),
        builder=build,
        configs=configs,
    )
