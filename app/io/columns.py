"""Column mapping: which dataset channel feeds each signal role an estimator needs.

An estimator declares roles (``y`` for a table filter's measured output; ``p_im``,
``omega_t`` … for an observer), each with the unit it expects. A run request maps roles to
dataset columns (``{"y": "nox_ppm"}``); :func:`map_columns` checks that mapping and reports
every problem by name: an unknown role, a column the dataset lacks, a required role left
unmapped, and (optionally) a unit that differs from the expected one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from app.io.errors import InputError
from estimation import Signals


@dataclass(frozen=True, slots=True)
class SignalRole:
    """A signal an estimator needs: its role name and the unit it expects (``""``: any)."""

    role: str
    unit: str = ""
    description: str = ""
    required: bool = True


@dataclass(frozen=True, slots=True)
class ColumnMapping:
    """role → dataset column and that column's unit; roles whose unit differs from the
    expected one (``role → (expected, actual)``) when units were not enforced."""

    columns: dict[str, str]
    units: dict[str, str]
    unit_mismatches: dict[str, tuple[str, str]] = field(default_factory=dict)


ChannelsLike = Mapping[str, str] | Sequence[Mapping[str, Any]] | Signals


def channel_units(channels: ChannelsLike) -> dict[str, str]:
    """``name → unit`` from a mapping, a ``[{"name", "unit"}]`` list or :class:`Signals`."""
    if isinstance(channels, Signals):
        return dict(channels.units)
    if isinstance(channels, Mapping):
        return {str(k): str(v) for k, v in channels.items()}
    return {str(c["name"]): str(c.get("unit", "")) for c in channels}


def map_columns(
    channels: ChannelsLike,
    roles: Sequence[SignalRole],
    mapping: Mapping[str, str],
    *,
    field: str = "signals",
    check_units: bool = False,
    default_to_role_name: bool = True,
) -> ColumnMapping:
    """Check ``mapping`` (role → column) against the dataset ``channels`` and ``roles``.

    A role missing from ``mapping`` maps to the column of the same name when
    ``default_to_role_name`` and that column exists. Raises :class:`InputError` with field
    ``<field>.<role>``.
    """
    units = channel_units(channels)
    known = {r.role: r for r in roles}
    for role in mapping:
        if role not in known:
            raise InputError(
                f"unknown signal role {role!r}; this estimator takes {sorted(known)}",
                field=f"{field}.{role}",
            )
    columns: dict[str, str] = {}
    found: dict[str, str] = {}
    mismatches: dict[str, tuple[str, str]] = {}
    for r in roles:
        column = mapping.get(r.role)
        if column is None and default_to_role_name and r.role in units:
            column = r.role
        if column is None:
            if r.required:
                raise InputError(
                    f"signal {r.role!r} is required"
                    + (f" ({r.description})" if r.description else "")
                    + f"; map it to one of the dataset's channels {sorted(units)}",
                    field=f"{field}.{r.role}",
                )
            continue
        if not isinstance(column, str) or column not in units:
            raise InputError(
                f"signal {r.role!r}: column {column!r} is not in the dataset; "
                f"its channels are {sorted(units)}",
                field=f"{field}.{r.role}",
            )
        actual = units[column]
        if r.unit and actual and not same_unit(r.unit, actual):
            if check_units:
                raise InputError(
                    f"signal {r.role!r}: column {column!r} is in {actual!r}, expected {r.unit!r}",
                    field=f"{field}.{r.role}",
                )
            mismatches[r.role] = (r.unit, actual)
        columns[r.role] = column
        found[r.role] = actual
    return ColumnMapping(columns, found, mismatches)


def require_columns(channels: ChannelsLike, names: Sequence[str], *, field: str) -> None:
    """Each of ``names`` must be a dataset channel (e.g. table axes: ``table.axes[i].name``)."""
    units = channel_units(channels)
    for i, name in enumerate(names):
        if name not in units:
            raise InputError(
                f"column {name!r} is not in the dataset; its channels are {sorted(units)}",
                field=f"{field}[{i}].name",
            )


_ALIASES = {"1/min": "rpm", "min^-1": "rpm", "u/min": "rpm", "°c": "degc", "deg c": "degc"}


def same_unit(a: str, b: str) -> bool:
    """Units equal up to case, spaces and a few common spellings (``rpm`` = ``1/min``)."""

    def norm(u: str) -> str:
        u = " ".join(u.strip().lower().split())
        return _ALIASES.get(u, u)

    return norm(a) == norm(b)
