"""Unit names as loggers write them: the check that a dataset column carries the unit an
estimator's signal role expects (``app.services.run_plan``)."""

from __future__ import annotations

_ALIASES = {
    "1/min": "rpm",
    "min^-1": "rpm",
    "u/min": "rpm",
    "°c": "degc",
    "deg c": "degc",
    "nm": "n·m",
    "n m": "n·m",
    "n*m": "n·m",
    "kg/(s pa)": "kg/(s·pa)",
}


def same_unit(a: str, b: str) -> bool:
    """Units equal up to case, spaces and a few common spellings (``rpm`` = ``1/min``,
    ``Nm`` = ``N·m``)."""

    def norm(u: str) -> str:
        u = " ".join(u.strip().lower().split())
        return _ALIASES.get(u, u)

    return norm(a) == norm(b)
