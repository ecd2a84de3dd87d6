"""Runs linked to an A2L map: the link checked at creation, and the exports it enables.

A run created with ``calibration: {ecu_id, map}`` adapts that MAP or CURVE of the ECU's
A2L; its table must have the map's shape (and a FIX_AXIS its fixed points). The link is
kept in the run's table (``table.calibration``). Its exports, docs/calibration.md#rest-and-cli:

- ``json``: the ``mapwise adapt`` document plus ``quantization_error`` (per cell, physical:
  stored − learned) and ``calibration`` (the link, the stored values, the clamped cells);
- ``dcm`` / ``cdfx``: the map keyed by its A2L name, values clamped to the limits and rounded
  to what the ECU's datatype and conversion hold (:func:`app.calibration.quantize.quantize`);
- ``image``: the ECU's HEX or S19 with only the map's bytes changed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import EcuRepo
from app.errors import AppError, ConflictError, InvalidRequestError, NotFoundError
from app.io.decimate import nested_or_none
from app.io.errors import InputError
from app.services.ecus import IMAGE_FORMATS, cache_limits, require_table
from estimation.table import Table

if TYPE_CHECKING:
    from app.calibration.a2l import A2lFile
    from app.calibration.model import Characteristic
    from app.calibration.quantize import Quantized
    from app.calibration.values import CalibrationValues
    from app.services.run_plan import CalibrationLink

CALIBRATION_FORMATS = ("cdfx", "image")  # exports only a linked run has
FIX_AXIS_RTOL = 1e-9


@dataclass(frozen=True, slots=True)
class LinkedMap:
    """A run's calibration link, resolved: the ECU's A2L and the characteristic."""

    ecu_id: int
    a2l: A2lFile
    char: Characteristic
    values_format: str | None

    def to_json(self) -> dict[str, Any]:
        return {"ecu_id": self.ecu_id, "map": self.char.name}


def resolve(db: Database, settings: Settings, ecu_id: int, name: str, *, field: str) -> LinkedMap:
    """The ECU's A2L and its MAP/CURVE ``name``; errors name ``field.ecu_id`` / ``field.map``."""
    from app.services.a2l_cache import open_cached

    with db.read() as s:
        try:
            ecu = EcuRepo(s).get(ecu_id)
        except NotFoundError as exc:
            raise NotFoundError(exc.message, field=f"{field}.ecu_id") from None

    def load() -> bytes:
        with db.read() as s:
            return EcuRepo(s).a2l(ecu_id)

    a2l = open_cached(ecu.a2l_sha256, load, cache_limits(settings))
    try:
        char = require_table(a2l.get(name), field=f"{field}.map")
    except InputError as exc:
        raise InvalidRequestError(str(exc), field=f"{field}.map") from None
    return LinkedMap(ecu_id, a2l, char, ecu.values_format)


def link_for_request(db: Database, settings: Settings, link: CalibrationLink) -> LinkedMap:
    return resolve(db, settings, link.ecu_id, link.map, field="calibration")


def check_table(char: Characteristic, table_spec: dict[str, Any] | None, estimator: str) -> None:
    """The run's table must be the map's: as many axes, no more points than the A2L allows,
    a FIX_AXIS's fixed points; 422 naming the field otherwise."""
    if table_spec is None:
        raise InvalidRequestError(
            f"{estimator} has no table to link to {char.name}", field="calibration"
        )
    axes = table_spec["axes"]
    if len(axes) != len(char.axes):
        raise InvalidRequestError(
            f"{char.name} is a {char.type} with {len(char.axes)} axes; the table has {len(axes)}",
            field="calibration.map",
        )
    for i, (mine, theirs) in enumerate(zip(axes, char.axes, strict=True)):
        points = len(mine["breakpoints"])
        if points > theirs.points:
            raise InvalidRequestError(
                f"{char.name}: axis {i} ({theirs.input_quantity}) holds at most "
                f"{theirs.points} points; the table has {points}",
                field=f"table.axes[{i}].breakpoints",
            )
        fixed = theirs.fix_axis_values
        if fixed is not None and not (
            len(fixed) == points
            and np.allclose(mine["breakpoints"], fixed, rtol=FIX_AXIS_RTOL, atol=0.0)
        ):
            raise InvalidRequestError(
                f"{char.name}: axis {i} ({theirs.input_quantity}) is a FIX_AXIS with points "
                f"{list(fixed)}; the table's must be the same",
                field=f"table.axes[{i}].breakpoints",
            )


def linked_run(
    db: Database, settings: Settings, table: dict[str, Any] | None, *, required: bool
) -> LinkedMap | None:
    """The link a stored run's table carries, resolved (``None`` without one). A link whose
    ECU or map is gone is ``None`` too, unless ``required``: then 409 naming ``format``."""
    link = (table or {}).get("calibration")
    if not link:
        return None
    try:
        return resolve(db, settings, int(link["ecu_id"]), str(link["map"]), field="calibration")
    except AppError as exc:
        if not required:
            return None
        raise ConflictError(
            f"the run's calibration link (ECU {link['ecu_id']}, {link['map']}) no longer "
            f"resolves: {exc.message}",
            field="format",
        ) from None


def learned_values(char: Characteristic, table: Table) -> CalibrationValues:
    """A learned map as calibration values named and united as the A2L says."""
    from app.calibration.values import CalibrationValues

    return CalibrationValues(
        name=char.name,
        axes=tuple(np.asarray(a.breakpoints, dtype=np.float64) for a in table.axes),
        values=np.asarray(table.values, dtype=np.float64),
        unit=char.unit,
        axis_units=tuple(a.unit for a in char.axes),
        axis_names=tuple(a.input_quantity for a in char.axes),
        description=char.description,
    )


def quantized(char: Characteristic, table: Table) -> tuple[CalibrationValues, Quantized]:
    """The learned values as the ECU stores them (clamped, rounded) and the quantisation."""
    from dataclasses import replace

    from app.calibration.quantize import quantize

    learned = learned_values(char, table)
    q = quantize(char, learned.values)
    return replace(learned, values=np.asarray(q.values, dtype=np.float64)), q


def json_extras(char: Characteristic, table: Table, link: dict[str, Any]) -> dict[str, Any]:
    """What the JSON map document of a map linked to ``char`` adds: ``quantization_error``
    (per cell, stored − learned, physical) and ``calibration`` (``link``, the stored values,
    the number of cells clamped to the limits)."""
    stored, q = quantized(char, table)
    clamped = np.asarray(q.clamped, dtype=bool)
    return {
        "quantization_error": nested_or_none(np.asarray(q.error, dtype=np.float64)),
        "calibration": link
        | {
            "map": char.name,
            "unit": char.unit,
            "limits": [char.lower, char.upper],
            "values": nested_or_none(stored.values),
            "clamped_cells": int(clamped.sum()),
        },
    }


def dcm_text(char: Characteristic, table: Table, *, description: str) -> str:
    """The map as DCM keyed by its A2L name, axes named after the input quantities."""
    from dataclasses import replace

    from app.calibration.values import write_dcm

    stored, _ = quantized(char, table)
    return write_dcm([(char, replace(stored, description=description))])


def cdfx_bytes(char: Characteristic, table: Table) -> bytes:
    """The map as CDFX (ASAM CDF 2.0) keyed by its A2L name."""
    from app.calibration.cdfx import write_cdfx

    stored, _ = quantized(char, table)
    return write_cdfx([(char, stored)])


def patched_image(a2l: A2lFile, char: Characteristic, table: Table, image: bytes) -> bytes:
    """``image`` (HEX or S19) with only the map's bytes changed to the stored values."""
    from app.calibration.image import patch_image

    stored, _ = quantized(char, table)
    return patch_image(a2l, char, stored, image)


def ecu_image(db: Database, linked: LinkedMap) -> tuple[bytes, str]:
    """The linked ECU's memory image and its format; 409 naming ``format`` without one."""
    with db.read() as s:
        ecu = EcuRepo(s).get(linked.ecu_id)
        image = EcuRepo(s).values(linked.ecu_id)
    if image is None or ecu.values_format not in IMAGE_FORMATS:
        held = "no values file" if image is None else f"a {ecu.values_format} values file"
        raise ConflictError(
            f"ECU {ecu.id} has {held}; a patched image needs its HEX or S19 image",
            field="format",
        )
    return image, str(ecu.values_format)
