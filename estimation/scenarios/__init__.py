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

The types are :mod:`estimation.scenarios.base`, the catalog :mod:`estimation.scenarios.catalog`,
and each family of scenarios has its module (:mod:`~estimation.scenarios.skf_sim`,
:mod:`~estimation.scenarios.nox`, :mod:`~estimation.scenarios.airpath`,
:mod:`~estimation.scenarios.torque`).
"""

from estimation.scenarios.base import Build, Scenario, ScenarioData, table_filter_config
from estimation.scenarios.catalog import get_scenario, scenarios

__all__ = ["Build", "Scenario", "ScenarioData", "get_scenario", "scenarios", "table_filter_config"]
