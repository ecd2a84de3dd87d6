"""One error hierarchy for the numerical core.

Every error also inherits the built-in a caller would naturally catch, so
``except ValueError`` keeps working (python-control / FilterPy style).
Messages quote the offending name and value.
"""


class EstimationError(Exception):
    """Base class of every error raised by :mod:`estimation`."""


class ShapeError(EstimationError, ValueError):
    """An array has the wrong shape or length."""


class ConfigError(EstimationError, ValueError):
    """A configuration value is out of range or inconsistent."""


class SignalError(EstimationError, ValueError):
    """A signal block is unusable: missing channel, non-finite value, bad time base."""


class StateError(EstimationError, ValueError):
    """A saved estimator state does not fit the estimator it is loaded into."""
