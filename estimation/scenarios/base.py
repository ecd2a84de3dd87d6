"""The scenario types: :class:`Scenario` (a catalog entry and how it is built),
:class:`Build` (what a builder is asked for), :class:`ScenarioData` (one realisation), and the
helpers every family of scenarios shares (metadata, truncation, table-filter configs).

The catalog itself is :mod:`estimation.scenarios.catalog`; the families are built in
:mod:`estimation.scenarios.skf_sim`, :mod:`~estimation.scenarios.nox`,
:mod:`~estimation.scenarios.airpath` and :mod:`~estimation.scenarios.torque`.
"""

from __future__ import annotations

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

    def check_duration(self, duration_s: float | None) -> None:
        """A duration to simulate is at least one sample interval (two samples), as the REST
        schema states per scenario, and at most the record; ``None`` is the whole record."""
        shortest = 1.0 / self.rate_hz
        if duration_s is not None and not shortest <= duration_s <= self.duration_s:
            raise ConfigError(
                f"duration must be in [{shortest:g}, {self.duration_s:g}] s for "
                f"{self.name!r}, got {duration_s:g}"
            )

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
        self.check_duration(duration_s)
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


def scenario_metadata(
    build: Build, draw: MismatchDraw | None, averaging: int | None
) -> dict[str, Any]:
    """:attr:`ScenarioData.metadata` of a realisation: mismatch level, truth kind, averaging,
    noise scale and the drawn estimator-side constants (``draw``; ``None``: none drawn)."""
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


def truncate(signals: Signals, duration_s: float | None) -> Signals:
    if duration_s is None:
        return signals
    stop = int(np.searchsorted(signals.time, signals.time[0] + duration_s, side="right"))
    return signals.slice(0, max(stop, 2))
