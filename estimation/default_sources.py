"""Where each estimator setting's default comes from: a paper's value, or a mapwise choice.

The dashboard shows one short "source" per config field (``GET /api/estimators``: each
property of ``config_schema`` carries ``"source"``), so an engineer sees whether a default is
the paper's (and which equation, section or table states it) or a mapwise default that no
paper gives. Entries restate what docs/algorithms.md and the config docstrings say (the
papers' short names are those of docs/algorithms.md#papers: SKF, LPV, EKF, TQ); a field not
listed here is a mapwise default. Never put a value here that those documents do not state.

Keyed by the config model's class name (looked up along its MRO) and field name; nested
models (``SensorConfig``) carry their own entries.
"""

from __future__ import annotations

from typing import Any

MAPWISE = "mapwise default"
"""The label of a default that no paper gives."""

_SKF5 = "SKF §5 (synthetic checks)"
_NOX = "SKF (34), NOx study"

SOURCES: dict[str, dict[str, str]] = {
    "TableFilterConfig": {"gate_sigma": f"{MAPWISE}: no gate"},
    "_Covariance": {
        "theta0": f"{_SKF5}: θ0 = 0",
        "sigma_w": f"{_SKF5}: σw² = 1 ({_NOX}: σw = 15)",
        "sigma_v": f"{_SKF5}: σv² = 1 ({_NOX}: σv = 25)",
        "p0": f"{_SKF5}: P0 = 0",
        "limit": f"{MAPWISE}: no limiting (EKF §3.1 limiting is optional)",
    },
    "KfConfig": {"sensor": f"{MAPWISE}: off ({_NOX}: a = 0.96, τ = 0.75 s, σf = 50)"},
    "SkfConfig": {"sensor": f"{MAPWISE}: off ({_NOX}: a = 0.96, τ = 0.75 s, σf = 50)"},
    "SensorConfig": {
        "lag": f"{_NOX}: a = 0.96",
        "delay_s": f"{_NOX}: τ = 0.75 s",
        "sigma_f": f"{_NOX}: σf² = 50²",
    },
    "SskfConfig": {
        "theta0": f"{_SKF5}: θ0 = 0",
        "sigma_w": f"{_SKF5}: σw² = 1 ({_NOX}: σw = 15)",
        "sigma_v": f"{_SKF5}: σv² = 1 ({_NOX}: σv = 25)",
    },
    "RlsConfig": {
        "forgetting": f"{MAPWISE} (no paper calibrates RLS)",
        "p0": f"{MAPWISE} (no paper calibrates RLS)",
    },
    "LpvConfig": {
        "adaptation": f"{MAPWISE}: normalised Γ (LPV (26): constant Γ = γI)",
        "gamma": f"{MAPWISE}: γ0 = 10 (LPV: γ = 200 with a constant Γ)",
        "eps1": "LPV (28): ε1 = 0.25",
        "eps2": "LPV (28): ε2 = 0.11",
        "a1": "from the observer's model",
        "a2": "from the observer's model",
        "model": f"{MAPWISE}: the simulator's nominal air path",
        "rho_min": f"{MAPWISE}: the data's ρ box (LPV Table 1 is a reference)",
        "rho_max": f"{MAPWISE}: the data's ρ box (LPV Table 1 is a reference)",
    },
    "EkfConfig": {
        "outputs": "EKF §5.2 (simulation study): the MAF only",
        "model": f"{MAPWISE}: the simulator's nominal air path",
        "limit": f"EKF §3.1 covariance limiting ({MAPWISE}: PSD-preserving form)",
    },
    "TorqueEstimatorConfig": {
        "J_nm_s_per_rpm": f"{MAPWISE}: 0.05 kg·m² (the bound TQ Table III implies)",
        "k": "TQ §VI: k = 0.01 s",
    },
    "SmoConfig": {"lambda1": "TQ §VI: λ1 = 150 N·m (simulation; 350 on the rig, §VII)"},
    "AdaptiveConfig": {
        "air_unit": "TQ Table I: kg/s",
        "ell": "TQ §VI: ℓ = 10 1/s",
        "gamma": "TQ (50): Γ = diag(0.1, 100)",
        "kappa": "TQ §VI: κ = 0.1 (compared with 0)",
        "theta0": "TQ: Θ̂(0) = 0",
    },
    "AdaptiveTvConfig": {
        "gamma": f"{MAPWISE}: Γ = 10·I by a declared rule (TQ (54) gives no value)",
        "K0": f"{MAPWISE} (TQ (52) gives no K0)",
    },
}


def source_of(model: type, field: str) -> str:
    """The source of ``model``'s default for ``field`` (:data:`MAPWISE` if none is listed)."""
    for cls in getattr(model, "__mro__", (model,)):
        entry = SOURCES.get(getattr(cls, "__name__", ""), {})
        if field in entry:
            return entry[field]
    return MAPWISE


def annotate(schema: dict[str, Any], model: type) -> dict[str, Any]:
    """``schema`` (``model.model_json_schema()``) with a ``"source"`` on every property of
    the model and of each nested model in ``$defs`` (by the nested model's name)."""
    out = dict(schema)
    out["properties"] = _annotated(schema.get("properties", {}), model)
    defs = dict(schema.get("$defs", {}))
    nested = _nested_models(model)
    for name, sub in defs.items():
        if name in nested:
            defs[name] = {**sub, "properties": _annotated(sub.get("properties", {}), nested[name])}
    if defs:
        out["$defs"] = defs
    return out


def _annotated(props: dict[str, Any], model: type) -> dict[str, Any]:
    return {k: {**v, "source": v.get("source") or source_of(model, k)} for k, v in props.items()}


def _nested_models(model: type) -> dict[str, type]:
    """Pydantic models used by ``model``'s fields (one level, and theirs), by class name."""
    found: dict[str, type] = {}
    stack = [model]
    while stack:
        current = stack.pop()
        for info in getattr(current, "model_fields", {}).values():
            for candidate in _types_in(info.annotation):
                if hasattr(candidate, "model_fields") and candidate.__name__ not in found:
                    found[candidate.__name__] = candidate
                    stack.append(candidate)
    return found


def _types_in(annotation: Any) -> list[type]:
    args = getattr(annotation, "__args__", None)
    if args:
        return [t for a in args for t in _types_in(a)]
    return [annotation] if isinstance(annotation, type) else []
