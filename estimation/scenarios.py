"""Named, seeded, reproducible scenarios: cycle + plant + sensor error + noise + truth.

Tests, benchmarks, the demo and the dashboard's "simulate" button all draw on this catalog.
``get_scenario(name).build(seed=…)`` returns the measured signals with units and the truth;
``default_config(estimator)`` is the config a map estimator starts from on that scenario
(the papers' settings), which callers may override key by key.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimation.errors import ConfigError
from estimation.signals import Signals
from estimation.table import Table

TABLE_FILTERS = ("kf", "skf", "sskf", "rls", "nlms")


@dataclass(frozen=True, slots=True, eq=False)
class ScenarioData:
    """One realisation of a scenario.

    ``true_map`` is the table a map estimator should recover (for a drifting map: its value
    at the end of the record); ``map_inputs`` are the channels of its axes, in order, and
    ``map_output`` the measured channel the table explains.
    """

    scenario: str
    seed: int
    signals: Signals
    truth: dict[str, Any]
    true_map: Table | None = None
    map_inputs: tuple[str, ...] = ()
    map_output: str | None = None


@dataclass(frozen=True, slots=True)
class Scenario:
    """A catalog entry: what the scenario is and how to build it."""

    name: str
    description: str
    rate_hz: float
    duration_s: float
    channels: tuple[tuple[str, str], ...]
    suggested: tuple[str, ...]
    builder: Callable[[int, float | None], ScenarioData] = field(repr=False)
    configs: Callable[[str], dict[str, Any]] = field(repr=False)

    def build(self, *, seed: int = 0, duration_s: float | None = None) -> ScenarioData:
        if duration_s is not None and not 0 < duration_s <= self.duration_s:
            raise ConfigError(
                f"duration must be in (0, {self.duration_s:g}] s for {self.name!r}, "
                f"got {duration_s:g}"
            )
        return self.builder(int(seed), duration_s)

    def default_config(self, estimator: str) -> dict[str, Any]:
        """The starting config of ``estimator`` on this scenario (papers' settings)."""
        config = self.configs(estimator)
        if not config:
            raise ConfigError(
                f"estimator {estimator!r} does not apply to scenario {self.name!r}; "
                f"suggested: {', '.join(self.suggested)}"
            )
        return config

    def catalog_entry(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "description": self.description,
            "rate_hz": self.rate_hz,
            "duration_s": self.duration_s,
            "channels": [{"name": n, "unit": u} for n, u in self.channels],
            "suggested_estimators": list(self.suggested),
        }


def table_filter_config(
    estimator: str,
    table: Table,
    output: str,
    *,
    output_unit: str = "",
    sigma_w: float,
    sigma_v: float,
    p0: float,
    sensor: dict[str, float] | None = None,
) -> dict[str, Any]:
    """A config for one of the five table filters on ``table``'s grid (only the keys that
    filter understands)."""
    if estimator not in TABLE_FILTERS:
        return {}
    config: dict[str, Any] = {
        "axes": [a.to_dict() for a in table.axes],
        "output": output,
        "output_unit": output_unit,
    }
    if estimator in ("kf", "skf", "sskf"):
        config |= {"sigma_w": sigma_w, "sigma_v": sigma_v}
    if estimator in ("kf", "skf"):
        config["p0"] = p0
        if sensor is not None:
            config["sensor"] = sensor
    if estimator in ("rls", "nlms"):
        config["sigma_v"] = sigma_v
    return config


def _truncate(signals: Signals, duration_s: float | None) -> Signals:
    if duration_s is None:
        return signals
    stop = int(np.searchsorted(signals.time, signals.time[0] + duration_s, side="right"))
    return signals.slice(0, max(stop, 2))


# --- SKF paper §5: the three synthetic problems ------------------------------------------


def _skf_sim(number: int) -> Scenario:
    from estimation.plants.synthetic import skf_sim, skf_sim_table

    def build(seed: int, duration_s: float | None) -> ScenarioData:
        signals, truth = skf_sim(number, seed=seed)  # type: ignore[arg-type]
        return ScenarioData(
            scenario=f"skf-sim{number}",
            seed=seed,
            signals=_truncate(signals, duration_s),
            truth=truth.to_dict(),
            true_map=truth.table,
            map_inputs=("u1", "u2"),
            map_output="y",
        )

    def configs(estimator: str) -> dict[str, Any]:
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


# --- SKF paper §6: NOx map behind a delayed, lagged sensor ------------------------------


def _nox(name: str, cycle: str, description: str, duration_s: float) -> Scenario:
    rate_hz = 50.0

    def build(seed: int, duration: float | None) -> ScenarioData:
        from estimation.cycles import load_cycle, make_sdmp
        from estimation.plants.nox import simulate_nox
        from estimation.vehicle import operating_points

        drive = make_sdmp(seed=seed) if cycle == "sdmp" else load_cycle(cycle)
        points = operating_points(drive, rate_hz=rate_hz)
        stop = points.time_s.size if duration is None else int(duration * rate_hz) + 1
        signals, truth = simulate_nox(
            points.time_s[:stop],
            points.speed_rpm[:stop],
            points.fuel_mg_per_cycle[:stop],
            seed=seed,
        )
        return ScenarioData(
            scenario=name,
            seed=seed,
            signals=signals,
            truth=truth.to_dict(),
            true_map=truth.final_map,
            map_inputs=("speed_rpm", "fuel_mg_per_stroke"),
            map_output="nox_ppm",
        )

    def configs(estimator: str) -> dict[str, Any]:
        from estimation.plants.nox import nox_base_map

        # SKF (34): σv = 25, σw = 15, σf = 50 ppm, a = 0.96, τ = 0.75 s at 50 Hz; T_NOx,0 = 0.
        sensor = {"lag": 0.96, "delay_s": 0.75, "sigma_f": 50.0}
        return table_filter_config(
            estimator,
            nox_base_map(),
            "nox_ppm",
            output_unit="ppm",
            sigma_w=15.0,
            sigma_v=25.0,
            p0=1.0e4,
            sensor=sensor,
        )

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


def _catalog() -> dict[str, Scenario]:
    scenarios = [
        _skf_sim(1),
        _skf_sim(2),
        _skf_sim(3),
        _nox(
            "nox-sdmp",
            "sdmp",
            "Engine-out NOx map (12×18, SKF (34)) drifting slowly, seen through a 0.75 s delay "
            "and a = 0.96 lag, on a sportive mountain drive with sharp load and speed changes.",
            1200.0,
        ),
        _nox(
            "nox-nedc",
            "nedc",
            "The same NOx map and sensor on the slow NEDC: poorer excitation (SKF §6.4).",
            1180.0,
        ),
    ]
    return {s.name: s for s in scenarios}


def scenarios() -> dict[str, Scenario]:
    """Every scenario by name."""
    return _catalog()


def get_scenario(name: str) -> Scenario:
    catalog = _catalog()
    try:
        return catalog[name]
    except KeyError:
        raise ConfigError(f"unknown scenario {name!r}; choose one of {sorted(catalog)}") from None
