"""Every estimator setting says where its default comes from (estimation.default_sources),
and every listed source names a real config field (no stale entries after a rename)."""

from __future__ import annotations

from app.services.catalog import config_schema
from estimation.default_sources import MAPWISE, SOURCES, _nested_models
from estimation.registry import registry


def _models() -> dict[str, type]:
    out: dict[str, type] = {}
    for spec in registry().values():
        for model in [spec.config_model, *_nested_models(spec.config_model).values()]:
            for cls in model.__mro__:
                if hasattr(cls, "model_fields"):
                    out.setdefault(cls.__name__, cls)
    return out


def test_every_shown_setting_has_a_source() -> None:
    for name, spec in registry().items():
        schema, _ = config_schema(spec)
        for key, prop in schema["properties"].items():
            assert prop.get("source"), f"{name}.{key} has no source"
        for def_name, sub in schema.get("$defs", {}).items():
            for key, prop in sub.get("properties", {}).items():
                assert prop.get("source"), f"{name}: {def_name}.{key} has no source"


def test_every_listed_source_names_a_config_field() -> None:
    models = _models()
    for cls_name, fields in SOURCES.items():
        assert cls_name in models, f"{cls_name} is no config model of a registered estimator"
        for field in fields:
            assert field in models[cls_name].model_fields, f"{cls_name}.{field} does not exist"


def test_the_kalman_filters_name_the_skf_paper_and_rls_says_mapwise() -> None:
    kf, _ = config_schema(registry()["kf"])
    assert kf["properties"]["sigma_w"]["source"].startswith("SKF §5")
    assert kf["properties"]["p0"]["source"].startswith("SKF §5")
    rls, _ = config_schema(registry()["rls"])
    assert rls["properties"]["forgetting"]["source"].startswith(MAPWISE)
