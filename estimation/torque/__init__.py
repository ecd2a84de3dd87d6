"""Engine torque estimation (TQ §III, §V; docs/algorithms.md §5): configs, states, estimators."""

from estimation.torque.config import (
    AdaptiveConstConfig,
    AdaptiveTvConfig,
    DirtyConfig,
    SmoConfig,
    TorqueEstimatorConfig,
    UioConfig,
)
from estimation.torque.estimators import (
    TORQUE_SPECS,
    TorqueEstimator,
    TorqueState,
    initial_state,
    run_chunk,
)

__all__ = [
    "TORQUE_SPECS",
    "AdaptiveConstConfig",
    "AdaptiveTvConfig",
    "DirtyConfig",
    "SmoConfig",
    "TorqueEstimator",
    "TorqueEstimatorConfig",
    "TorqueState",
    "UioConfig",
    "initial_state",
    "run_chunk",
]
