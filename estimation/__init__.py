"""mapwise numerical core: look-up tables, map-updating filters, observers and plants.

Pure numerics (numpy + numba); nothing here knows about HTTP or databases.
"""

from estimation.errors import (
    ConfigError,
    EstimationError,
    ShapeError,
    SignalError,
    StateError,
)
from estimation.signals import Signals
from estimation.table import Axis, Table

__all__ = [
    "Axis",
    "ConfigError",
    "EstimationError",
    "ShapeError",
    "SignalError",
    "Signals",
    "StateError",
    "Table",
]
