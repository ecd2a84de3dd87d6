"""ECUs: an A2L with the ECU's current values; its maps listed, decoded and turned into a
run's table or a base map (docs/calibration.md#rest-and-cli).

An upload is checked whole before anything is stored: the A2L must parse (422 naming
``a2l``), the values file must be a HEX, S19, DCM or CDFX (422 naming ``values``); the
names a DCM or CDFX holds that the A2L does not know are reported as notes, not errors.
Values are decoded per map, when the map is used (its values, its New-run template, a base
map of it): a HEX that does not cover the map, a DCM whose axis points disagree with the A2L
or values beyond the A2L limits (:func:`app.calibration.values.check_limits`) are a 422
naming the map, the cell and the limit then, and nothing is stored. One map out of its
limits does not refuse the ECU's other maps (docs/calibration.md#rest-and-cli).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import BaseMapRepo, DatasetRepo, EcuRepo
from app.domain import BaseMap, Ecu, Page
from app.errors import ConflictError, InvalidRequestError
from app.io.decimate import finite_or_none, nested_or_none
from app.io.errors import InputError, too_large
from app.io.names import check_name, without_refused
from app.services.a2l_cache import CacheLimits, open_bytes, open_cached
from app.services.admission import OverBudgetError

if TYPE_CHECKING:
    from app.calibration.a2l import A2lFile
    from app.calibration.model import Characteristic
    from app.calibration.values import CalibrationValues

NAME_MAX = 200
TABLE_TYPES = ("CURVE", "MAP")  # what a run's table can be
VALUES_FORMATS = ("hex", "s19", "dcm", "cdfx")
IMAGE_FORMATS = ("hex", "s19")


@dataclass(frozen=True, slots=True)
class Uploaded:
    """A stored ECU and what the upload check noticed without refusing it."""

    ecu: Ecu
    notes: list[str]


def cache_limits(settings: Settings) -> CacheLimits:
    return CacheLimits(settings.a2l_cache_dir, settings.cache_files, settings.cache_bytes)


def values_json(values: CalibrationValues) -> dict[str, Any]:
    """Decoded values as JSON: axis points per axis, the values nested in axis order."""
    array = np.asarray(values.values, dtype=np.float64)
    return {
        "axes": [finite_or_none(np.asarray(a, dtype=np.float64)) for a in values.axes],
        "values": nested_or_none(array) if array.ndim else finite_or_none(array.reshape(1))[0],
        "unit": values.unit,
        "axis_units": list(values.axis_units),
    }


def require_table(char: Characteristic, *, field: str = "map") -> Characteristic:
    """``char`` if it is a CURVE or MAP (a run's table); else 422 naming ``field``."""
    if char.type not in TABLE_TYPES:
        raise InvalidRequestError(
            f"{char.name} is a {char.type}; only a MAP or CURVE defines a table", field=field
        )
    return char


class EcuService:
    def __init__(self, db: Database, settings: Settings) -> None:
        self.db = db
        self.settings = settings
        self.limits = cache_limits(settings)

    # -- upload ---------------------------------------------------------------------------------

    def upload(
        self,
        a2l: bytes,
        *,
        values: bytes | None,
        name: str | None,
        filename: str | None,
    ) -> Uploaded:
        """Parse the A2L and check the values file; store both only if both are usable."""
        given = _ecu_name(name, filename)  # a bad name fails before the file is read
        self._check_size(a2l, "a2l")
        if not a2l.strip():
            raise InputError("the A2L file is empty", field="a2l")
        parsed = open_bytes(a2l, self.limits)
        fmt, notes = (None, []) if values is None else self._check_values(parsed, values)
        with self.db.write() as s:
            ecu = EcuRepo(s).add(
                name=given,
                a2l_sha256=parsed.sha256,
                a2l=a2l,
                characteristics=len(parsed.characteristics),
                values_format=fmt,
                values=values,
            )
        return Uploaded(ecu, notes)

    def set_values(self, ecu_id: int, values: bytes) -> Uploaded:
        """Replace the ECU's values file (checked against its A2L first)."""
        a2l = self.a2l(ecu_id)
        fmt, notes = self._check_values(a2l, values)
        with self.db.write() as s:
            return Uploaded(EcuRepo(s).set_values(ecu_id, values_format=fmt, values=values), notes)

    def _check_size(self, data: bytes, field: str) -> None:
        if len(data) > self.settings.max_whole_bytes:
            raise too_large(
                f"the {field} file has {len(data):,} bytes, more than the limit of "
                f"{self.settings.max_whole_bytes:,} (MAPWISE_MAX_WHOLE_MB)",
                field=field,
            )

    def _check_values(self, a2l: A2lFile, data: bytes) -> tuple[str, list[str]]:
        """The values file's format, and notes naming what in it the A2L does not know."""
        from app.calibration.values import detect_values_format

        self._check_size(data, "values")
        if not data.strip():
            raise InputError("the values file is empty", field="values")
        fmt = _as_values_field(detect_values_format, data)
        if fmt not in VALUES_FORMATS:
            raise InputError(
                f"the values file is {fmt!r}; expected one of {', '.join(VALUES_FORMATS)}",
                field="values",
            )
        names = _as_values_field(_value_names, fmt, data)
        known = {c.name for c in a2l.characteristics} | set(a2l.axis_pts)
        unknown = [n for n in names if n not in known]
        notes = []
        if unknown:
            more = f" … ({len(unknown)} in all)" if len(unknown) > 20 else ""
            shown = ", ".join(unknown[:20]) + more
            notes.append(f"not in the A2L, ignored: {shown}")
        return fmt, notes

    # -- reading --------------------------------------------------------------------------------

    def get(self, ecu_id: int) -> Ecu:
        with self.db.read() as s:
            return EcuRepo(s).get(ecu_id)

    def list(self, *, limit: int, offset: int) -> Page[Ecu]:
        with self.db.read() as s:
            return EcuRepo(s).list(limit=limit, offset=offset)

    def delete(self, ecu_id: int) -> None:
        with self.db.write() as s:
            EcuRepo(s).delete(ecu_id)

    def a2l(self, ecu_id: int) -> A2lFile:
        """The ECU's parsed A2L (from the cache when it is there)."""
        ecu = self.get(ecu_id)

        def load() -> bytes:
            with self.db.read() as s:
                return EcuRepo(s).a2l(ecu_id)

        return open_cached(ecu.a2l_sha256, load, self.limits)

    def values_file(self, ecu_id: int) -> tuple[str | None, bytes | None]:
        with self.db.read() as s:
            ecu = EcuRepo(s).get(ecu_id)
            return ecu.values_format, EcuRepo(s).values(ecu_id)

    def maps(
        self, ecu_id: int, *, query: str, types: tuple[str, ...], limit: int, offset: int
    ) -> tuple[int, list[dict[str, Any]]]:
        """The characteristics matching ``query`` (name or description) and ``types``."""
        total, items = self.a2l(ecu_id).search(query=query, types=types, limit=limit, offset=offset)
        return total, [c.to_json() for c in items]

    def current_values(
        self, ecu_id: int, name: str, *, table: bool = False
    ) -> tuple[Characteristic, CalibrationValues | None]:
        """The characteristic ``name`` (with ``table``: a MAP or CURVE, else 422) and its
        values decoded from the ECU's values file (``None`` without one)."""
        from app.calibration.values import read_values

        a2l = self.a2l(ecu_id)
        char = require_table(a2l.get(name)) if table else a2l.get(name)
        _, data = self.values_file(ecu_id)
        return char, None if data is None else read_values(a2l, char, data)

    def map(self, ecu_id: int, name: str) -> dict[str, Any]:
        """A characteristic's summary with its current values."""
        char, values = self.current_values(ecu_id, name)
        return char.to_json() | {"values": None if values is None else values_json(values)}

    def template(self, ecu_id: int, name: str, dataset_id: int | None) -> dict[str, Any]:
        """What New run needs to adapt map ``name``: the table (axes named after the
        dataset's channels where the input quantities match them), the units and limits,
        the current values as base map, and what did not match."""
        from app.calibration.matching import match_channels

        char, values = self.current_values(ecu_id, name, table=True)
        channels: list[str] = []
        if dataset_id is not None:
            with self.db.read() as s:
                channels = [c.name for c in DatasetRepo(s).get(dataset_id).channels]
        quantities = [a.input_quantity for a in char.axes]
        match = match_channels(quantities, channels)
        output = match_channels([char.name], channels).matched.get(char.name)
        axes = []
        for i, axis in enumerate(char.axes):
            breakpoints = _breakpoints(char, values, i)
            axes.append(
                {
                    "name": match.matched.get(axis.input_quantity, axis.input_quantity),
                    "quantity": axis.input_quantity,
                    "breakpoints": breakpoints,
                    "unit": axis.unit,
                }
            )
        return {
            "table": {
                "axes": axes,
                "output_unit": char.unit,
                "limits": [char.lower, char.upper],
            },
            "output": output,
            "base_map": None if values is None else values_json(values),
            "channels": {"matched": dict(match.matched), "unmatched": list(match.unmatched)},
            "calibration": {"ecu_id": ecu_id, "map": char.name},
        }

    def base_map(self, ecu_id: int, name: str) -> BaseMap:
        """A base map ``<ECU name>:<MAP>`` holding the map's current values."""
        from estimation.errors import EstimationError
        from estimation.table import Axis

        ecu = self.get(ecu_id)
        char, values = self.current_values(ecu_id, name, table=True)
        if values is None:
            raise ConflictError(
                f"ECU {ecu_id} has no values file; upload one (PUT /api/ecus/{ecu_id}/values)",
                field="values",
            )
        array = np.asarray(values.values, dtype=np.float64)
        cap = self.settings.max_cells
        if array.size > cap:
            raise OverBudgetError(
                f"{char.name} has {array.size:,} cells > {cap:,}, the cap (MAPWISE_MAX_CELLS)",
                field="map",
            )
        axes = []
        for i, axis in enumerate(char.axes):
            try:
                points = Axis(axis.input_quantity, axis.unit, np.asarray(values.axes[i]))
            except EstimationError as exc:
                raise InvalidRequestError(f"{char.name}: {exc}", field="map") from exc
            axes.append(points.to_dict())
        if not np.all(np.isfinite(array)):
            raise InvalidRequestError(f"{char.name} holds non-finite values", field="map")
        with self.db.write() as s:
            return BaseMapRepo(s).add(
                name=f"{ecu.name}:{char.name}"[:NAME_MAX],
                source="ecu",
                axes=axes,
                values=array.reshape(tuple(len(a["breakpoints"]) for a in axes)),
            )


def _breakpoints(
    char: Characteristic, values: CalibrationValues | None, axis: int
) -> list[float | None] | None:
    """An axis' points: from the values file, else the A2L's FIX_AXIS values, else unknown."""
    if values is not None and axis < len(values.axes):
        return finite_or_none(np.asarray(values.axes[axis], dtype=np.float64))
    fixed = char.axes[axis].fix_axis_values
    return None if fixed is None else [float(x) for x in fixed]


def _value_names(fmt: str, data: bytes) -> list[str]:
    """The characteristic names a DCM or CDFX file holds; a memory image holds none, it
    only has to read as one (records, checksums)."""
    if fmt in IMAGE_FORMATS:
        from app.calibration.memory_image import Memory

        Memory(data, "the values file")
        return []
    if fmt == "cdfx":
        from app.calibration.cdfx import read_cdfx

        return list(read_cdfx(data))
    if fmt == "dcm":
        from app.calibration.values import read_dcm_values

        return list(read_dcm_values(data))
    raise AssertionError(fmt)  # every format of VALUES_FORMATS is handled above


def _as_values_field(function: Any, *args: Any) -> Any:
    """``function(*args)`` with an input error about the file reported on field ``values``."""
    try:
        return function(*args)
    except InputError as exc:
        if exc.field in (None, "file", "values"):
            raise InputError(str(exc), field="values", code=exc.code) from None
        raise


def _ecu_name(name: str | None, filename: str | None) -> str:
    """The name as given (422 for a control or format character), else the A2L file's stem."""
    if name is not None and name.strip():
        return check_name(name, field="name", what="ECU name")[:NAME_MAX]
    stem = Path(without_refused((filename or "").replace("\\", "/").rsplit("/", 1)[-1])).stem
    return (stem.strip() or "ECU")[:NAME_MAX]
