"""Named, seeded, reproducible scenarios: cycle + plant + sensor error + noise + truth.

Tests, benchmarks, the demo and the dashboard's "simulate" button all draw on this catalog.
``get_scenario(name).build(seed=…, mismatch=…)`` returns the measured signals with units and
the truth; ``default_config(estimator, data=…)`` is the config a map estimator starts from on
that realisation (the papers' settings with the estimator-side model constants of the
realisation), which callers may override key by key.

``mismatch`` (:mod:`estimation.mismatch`, docs/fidelity.md) is ``"nominal"`` by default: the
true maps are smooth functions evaluated off-grid (:mod:`estimation.truth_maps`) and the
estimators' model constants are drawn around the plant's; ``"none"`` is the perfect-model
setting (the estimators' constants are the plant's, the truth a table on their grid);
``"severe"`` doubles the ranges. ``ScenarioData.metadata`` records the level, the logging
(sensor averaging) and every drawn constant beside the plant's.

``noise_scale`` (default 1) multiplies every sensor noise σ of the plant's logging, the
estimators' own σ settings staying as configured: the robustness study's unexpected noise
level (0: noise-free logs). ``transient_24s`` (``torque-si`` only) adds TQ §VI's set-point step
at 24 s (:func:`estimation.plants.torque.simulate_si_torque`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimation.errors import ConfigError
from estimation.mismatch import MismatchDraw, MismatchLevel, check_level
from estimation.registry import EstimatorKind, names
from estimation.signals import Signals
from estimation.table import Table


@dataclass(frozen=True, slots=True, eq=False)
class ScenarioData:
    """One realisation of a scenario.

    ``true_map`` is the table a map estimator should recover (for a drifting map: its value
    at the end of the record); ``map_inputs`` are the channels of its axes, in order, and
    ``map_output`` the measured channel the table explains (``None`` when the map is only
    seen through a model, as a MAF error). ``map_points`` are the true operating points
    ``(n, d)`` the map is scored along; by default the ``map_inputs`` channels.
    ``scored_series`` maps an estimator output name (e.g. ``torque_nm``, ``w_c_kg_s``) to its
    true series, one value per sample, which ``mapwise run`` scores the estimate against.

    With an off-grid truth (``mismatch`` not ``"none"``) ``true_map`` is the true function at
    the nodes and ``true_along`` its value at each scoring point, which the map metrics use
    (:func:`estimation.metrics.map_metrics`). ``metadata`` holds ``mismatch``, ``truth``
    (``"table"`` or ``"function"``), ``averaging`` (sensor readings averaged per logged
    sample, ``None`` where the scenario has no such sensors), ``noise_scale`` (the factor on
    every sensor noise σ of the log; the noise σ under ``parameters`` are the stated
    logging's, which the estimators' are drawn around) and ``parameters`` (every
    estimator-side constant beside the plant's, :class:`estimation.mismatch.MismatchDraw`);
    ``estimator_params`` maps those names to the estimator-side values.
    """

    scenario: str
    seed: int
    signals: Signals
    truth: dict[str, Any]
    true_map: Table | None = None
    map_inputs: tuple[str, ...] = ()
    map_output: str | None = None
    map_points: np.ndarray | None = None
    scored_series: dict[str, np.ndarray] = field(default_factory=dict)
    true_along: np.ndarray | None = None
    metadata: dict[str, Any] = field(default_factory=dict)
    estimator_params: dict[str, float] = field(default_factory=dict)

    @property
    def mismatch(self) -> str:
        return str(self.metadata.get("mismatch", "none"))

    def scoring_points(self) -> np.ndarray:
        if self.true_map is None:
            raise ConfigError(f"scenario {self.scenario!r} has no true map to score along")
        if self.map_points is not None:
            return self.map_points
        return self.signals.stack(list(self.map_inputs))


@dataclass(frozen=True, slots=True)
class Scenario:
    """A catalog entry: what the scenario is and how to build it."""

    name: str
    description: str
    rate_hz: float
    duration_s: float
    channels: tuple[tuple[str, str], ...]
    suggested: tuple[str, ...]
    builder: Callable[[Build], ScenarioData] = field(repr=False)
    configs: Callable[..., dict[str, Any] | None] = field(repr=False)
    """``configs(estimator, drawn=None)``: the config, ``None`` where it does not apply."""
    logging: str = "single readings per logged sample"
    averaging: int | None = None
    options: tuple[str, ...] = ()
    """Scenario-specific build options this entry accepts (``"transient_24s"``)."""

    def build(
        self,
        *,
        seed: int = 0,
        duration_s: float | None = None,
        mismatch: MismatchLevel = "nominal",
        averaging: int | None = None,
        noise_scale: float = 1.0,
        transient_24s: bool = False,
    ) -> ScenarioData:
        """One realisation. ``averaging``: sensor readings averaged per logged sample
        (air-path scenarios only; default: the scenario's stated logging, ``self.logging``).
        ``noise_scale``: factor on every sensor noise σ of the log, in [0, 100] (the
        estimators' σ settings are not scaled). ``transient_24s``: ``torque-si`` only, TQ
        §VI's transient at 24 s."""
        # At least one sample interval (two samples), as the REST schema states per scenario.
        shortest = 1.0 / self.rate_hz
        if duration_s is not None and not shortest <= duration_s <= self.duration_s:
            raise ConfigError(
                f"duration must be in [{shortest:g}, {self.duration_s:g}] s for "
                f"{self.name!r}, got {duration_s:g}"
            )
        level = check_level(mismatch)
        if averaging is not None:
            if self.averaging is None:
                raise ConfigError(
                    f"averaging applies to the air-path scenarios; {self.name!r} logs "
                    f"{self.logging}"
                )
            if isinstance(averaging, bool) or not isinstance(averaging, int | np.integer):
                raise ConfigError(f"averaging must be an integer ≥ 1, got {averaging!r}")
            if not 1 <= averaging <= 1000:
                raise ConfigError(f"averaging must be in [1, 1000] readings, got {averaging}")
        if isinstance(noise_scale, bool) or not isinstance(noise_scale, int | float | np.number):
            raise ConfigError(f"noise_scale must be a number in [0, 100], got {noise_scale!r}")
        if not (np.isfinite(noise_scale) and 0.0 <= noise_scale <= 100.0):
            raise ConfigError(f"noise_scale must be in [0, 100], got {noise_scale!r}")
        if transient_24s and "transient_24s" not in self.options:
            raise ConfigError(
                f"transient_24s applies to the torque-si scenario (TQ §VI), not {self.name!r}"
            )
        return self.builder(
            Build(
                int(seed),
                duration_s,
                level,
                averaging,
                float(noise_scale),
                bool(transient_24s),
            )
        )

    def default_config(self, estimator: str, data: ScenarioData | None = None) -> dict[str, Any]:
        """The starting config of ``estimator`` on this scenario (papers' settings). With
        ``data`` (a realisation of this scenario), the estimator-side model constants drawn
        for it (``data.estimator_params``); without, the estimators' documented defaults."""
        if data is not None and data.scenario != self.name:
            raise ConfigError(f"data of {data.scenario!r} given for scenario {self.name!r}")
        config = self.configs(estimator, {} if data is None else data.estimator_params)
        if config is None:
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
            "logging": self.logging,
            "options": list(self.options),
        }


@dataclass(frozen=True, slots=True)
class Build:
    """What a builder is asked for: seed, duration (``None``: whole record), mismatch level,
    sensor averaging (``None``: the scenario's stated logging), the factor on every sensor
    noise σ of the log (``noise_scale``) and, for ``torque-si``, TQ's 24 s transient."""

    seed: int
    duration_s: float | None
    mismatch: MismatchLevel
    averaging: int | None
    noise_scale: float = 1.0
    transient_24s: bool = False

    def draw(self, scenario: str) -> MismatchDraw:
        return MismatchDraw(scenario, self.seed, self.mismatch)

    @property
    def off_grid(self) -> bool:
        return self.mismatch != "none"


def _metadata(build: Build, draw: MismatchDraw | None, averaging: int | None) -> dict[str, Any]:
    return {
        "mismatch": build.mismatch,
        "truth": "function" if build.off_grid else "table",
        "averaging": averaging,
        "noise_scale": build.noise_scale,
        "parameters": [] if draw is None else list(draw.records),
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
) -> dict[str, Any] | None:
    """A config for one of the five table filters on ``table``'s grid (only the keys that
    filter understands); ``None`` for any other estimator."""
    if estimator not in names(EstimatorKind.MAP_FILTER):
        return None
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
            signals=_truncate(signals, b.duration_s),
            truth=truth.to_dict(),
            true_map=truth.table,
            map_inputs=("u1", "u2"),
            map_output="y",
            metadata=_metadata(b, None, None),
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


# --- SKF paper §6: NOx map behind a delayed, lagged sensor ------------------------------


def _nox(name: str, cycle: str, description: str, duration_s: float) -> Scenario:
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
            metadata=_metadata(b, draw, None),
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


# --- LPV and EKF papers: MAF-sensor error maps on the diesel air path --------------------

# The LPV paper's light-duty engine spans u_δ = 0…56 mg/cycle and n_e up to 3000 rpm (LPV §4);
# the WHTC is denormalised (GTR 4) for an engine of that size: rated 3000 rpm, 280 N·m.
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


def _maf(name: str, cycle: str, kind: str, description: str, duration_s: float) -> Scenario:
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
        metadata = _metadata(b, draw, averaging)
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


# --- Torque paper: effective torque from speed, load and air flow -------------------------


def _torque(name: str, description: str, channels: tuple[tuple[str, str], ...]) -> Scenario:
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
        metadata = _metadata(b, draw, None)
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
        _maf(
            "maf-whtc",
            "whtc",
            "2d",
            "2.0 L diesel air path (EGR, VGT) on the WHTC (standing in for the ETC) with an "
            "additive MAF error map ΔW_c(u_δ, n_e) on the LPV grid 0:4:56 mg × 0:250:3000 rpm; "
            "sensors logged at 10 Hz as the mean of ten 10 ms ECU readings.",
            1800.0,
        ),
        _maf(
            "maf-ftp75",
            "ftp75",
            "2d",
            "The same air path, MAF error map and sensors on the FTP-75 (LPV §4's second case).",
            1874.0,
        ),
        _maf(
            "maf-1d-whtc",
            "whtc",
            "1d",
            "The air path on the WHTC with a relative MAF error W_meas = (1 + q(W))·W, q a 1-D "
            "map over W (EKF (6), §5).",
            1800.0,
        ),
        _torque(
            "torque-si",
            "2.0 L SI engine mean value model (TQ (1)–(8)) with firing ripple under a speed "
            "profile 2200→2500→2200→1900 rpm (TQ §VI); noise N(0, 20) on speed and load.",
            (("speed_rpm", "rpm"), ("load_torque_nm", "N·m"), ("air_mass_flow_kg_s", "kg/s")),
        ),
        _torque(
            "torque-rig",
            "Diesel engine on a dynamometer: sine-sweep speed 1000–2500 rpm, load 0–300 N·m "
            "(TQ §VII); noise N(0, 20) on the load, σ = 1 rpm on the speed (TQ Table VI).",
            (("speed_rpm", "rpm"), ("load_torque_nm", "N·m"), ("air_mass_flow_kg_s", "kg/s")),
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
