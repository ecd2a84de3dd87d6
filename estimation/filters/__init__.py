"""Map-updating filters for look-up tables: KF, SKF, SSKF, RLS, NLMS (docs/algorithms.md §2)."""

from estimation.filters.estimator import FILTER_SPECS, TableFilter
from estimation.filters.functions import initial_state, run_chunk, variance
from estimation.filters.state import FilterState, KfState, LocalState, ThetaState

__all__ = [
    "FILTER_SPECS",
    "FilterState",
    "KfState",
    "LocalState",
    "TableFilter",
    "ThetaState",
    "initial_state",
    "run_chunk",
    "variance",
]
