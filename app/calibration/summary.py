"""The cached JSON summary of a parsed A2L, and its round trip to the model.

One JSON document per A2L (``<sha256>.json`` in the cache directory, see
``docs/calibration.md#a2l-import``)::

    {"version": 1, "module": "Example", "warnings": ["..."], "skipped": {"ASCII": 2},
     "compu_methods": {name: CompuMethod fields},
     "record_layouts": {name: RecordLayout fields},
     "axis_pts": [AxisPts fields, record_layout and compu_method by name],
     "characteristics": [Characteristic fields, likewise by name; axes inline]}

Conversions and layouts are stored once and shared by name, so a 2 MB A2L's summary
stays a fraction of the A2L and loads in tens of milliseconds.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from app.calibration.model import (
    IDENTICAL,
    AxisDescr,
    AxisPts,
    Characteristic,
    CompuMethod,
    LayoutItem,
    RecordLayout,
)

VERSION = 1


@dataclass
class Summary:
    """Everything the A2L import keeps of one A2L."""

    module: str = ""
    characteristics: list[Characteristic] = field(default_factory=list)
    axis_pts: dict[str, AxisPts] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    skipped: dict[str, int] = field(default_factory=dict)


def to_json(summary: Summary) -> dict[str, Any]:
    """The JSON document of ``summary`` (shared objects by name)."""
    methods: dict[str, Any] = {}
    layouts: dict[str, Any] = {}

    def method(cm: CompuMethod) -> str:
        methods.setdefault(cm.name, asdict(cm))
        return cm.name

    def layout(rl: RecordLayout) -> str:
        layouts.setdefault(rl.name, asdict(rl))
        return rl.name

    def axis(ax: AxisDescr) -> dict[str, Any]:
        return {**_fields(ax), "compu_method": method(ax.compu_method)}

    characteristics = [
        {
            **_fields(c),
            "record_layout": layout(c.record_layout),
            "compu_method": method(c.compu_method),
            "axes": [axis(ax) for ax in c.axes],
        }
        for c in summary.characteristics
    ]
    axis_pts = [
        {
            **_fields(a),
            "record_layout": layout(a.record_layout),
            "compu_method": method(a.compu_method),
        }
        for a in summary.axis_pts.values()
    ]
    return {
        "version": VERSION,
        "module": summary.module,
        "warnings": summary.warnings,
        "skipped": summary.skipped,
        "compu_methods": methods,
        "record_layouts": layouts,
        "axis_pts": axis_pts,
        "characteristics": characteristics,
    }


def from_json(doc: dict[str, Any]) -> Summary:
    """Rebuild the model from :func:`to_json`'s document. ``ValueError`` on another version."""
    if doc.get("version") != VERSION:
        raise ValueError(f"A2L summary version {doc.get('version')!r}, expected {VERSION}")
    methods = {name: _compu_method(d) for name, d in doc["compu_methods"].items()}
    methods.setdefault(IDENTICAL.name, IDENTICAL)
    layouts = {name: _record_layout(d) for name, d in doc["record_layouts"].items()}

    def axis(d: dict[str, Any]) -> AxisDescr:
        fix = d["fix_axis_values"]
        return AxisDescr(
            **{
                **d,
                "compu_method": methods[d["compu_method"]],
                "fix_axis_values": tuple(fix) if fix is not None else None,
            }
        )

    characteristics = [
        Characteristic(
            **{
                **d,
                "record_layout": layouts[d["record_layout"]],
                "compu_method": methods[d["compu_method"]],
                "axes": tuple(axis(a) for a in d["axes"]),
                "shape": tuple(d["shape"]),
                "extended_limits": _pair(d["extended_limits"]),
            }
        )
        for d in doc["characteristics"]
    ]
    axis_pts = {
        d["name"]: AxisPts(
            **{
                **d,
                "record_layout": layouts[d["record_layout"]],
                "compu_method": methods[d["compu_method"]],
            }
        )
        for d in doc["axis_pts"]
    }
    return Summary(
        module=doc["module"],
        characteristics=characteristics,
        axis_pts=axis_pts,
        warnings=list(doc["warnings"]),
        skipped=dict(doc["skipped"]),
    )


def _fields(obj: Any) -> dict[str, Any]:
    """The dataclass' own fields, nested objects left for the caller to reference."""
    return {name: getattr(obj, name) for name in obj.__dataclass_fields__}


def _pair(value: list[float] | None) -> tuple[float, float] | None:
    return (value[0], value[1]) if value is not None else None


def _compu_method(d: dict[str, Any]) -> CompuMethod:
    return CompuMethod(
        **{
            **d,
            "coeffs": tuple(d["coeffs"]),
            "table": tuple((raw, phys) for raw, phys in d["table"]),
            "verbal": tuple((raw, text) for raw, text in d["verbal"]),
            "verbal_ranges": tuple((lo, hi, text) for lo, hi, text in d["verbal_ranges"]),
        }
    )


def _record_layout(d: dict[str, Any]) -> RecordLayout:
    return RecordLayout(
        **{
            **d,
            "items": tuple(LayoutItem(**item) for item in d["items"]),
            "fix_no_axis_pts": tuple((axis, n) for axis, n in d["fix_no_axis_pts"]),
            "alignment": tuple((key, n) for key, n in d["alignment"]),
        }
    )
