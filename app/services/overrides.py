"""Estimator config overrides: a base config with changes applied, section by section."""

from __future__ import annotations

from typing import Any


def merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``overrides`` applied recursively (a ``null`` section removes it).

    A dict value merges into the dict of the same key; any other value replaces it. Neither
    argument is modified.
    """
    out = dict(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out
