"""ECUs: upload an A2L (with the current values), browse and decode its maps, prefill a run,
make a base map (docs/rest-api.md#ecus).

Every endpoint is a plain function (the thread pool runs it): parsing an A2L takes seconds
the first time, and the event loop must not wait for it.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, Query, Response, UploadFile

from app.api.deps import MAX_ID, Id, ServicesDep
from app.api.schemas import ERRORS, BaseMapOut, PageOut
from app.api.schemas_ecus import EcuOut, MapOut, MapsOut, TemplateOut
from app.calibration.model import CHARACTERISTIC_TYPES
from app.errors import InvalidRequestError
from app.io.errors import InputError
from app.io.names import name_schema

router = APIRouter(prefix="/ecus", tags=["ecus"], responses=ERRORS)

TYPES_PATTERN = r"^(MAP|CURVE|VAL_BLK|VALUE)(,(MAP|CURVE|VAL_BLK|VALUE))*$"
Limit = Annotated[int, Query(ge=1, le=500)]
Offset = Annotated[int, Query(ge=0, le=MAX_ID)]


def _read(upload: UploadFile, field: str, max_bytes: int) -> bytes:
    """The uploaded file's bytes; one more than the limit is enough to refuse it."""
    data = upload.file.read(max_bytes + 1)
    if not data:
        raise InputError(f"the {field} file is empty", field=field)
    return data


def _types(raw: str | None) -> tuple[str, ...]:
    if raw is None or not raw.strip():
        return ()
    types = tuple(t.strip().upper() for t in raw.split(",") if t.strip())
    bad = [t for t in types if t not in CHARACTERISTIC_TYPES]
    if bad:
        raise InvalidRequestError(
            f"unknown characteristic type {bad[0]!r}; "
            f"choose from {', '.join(CHARACTERISTIC_TYPES)}",
            field="type",
        )
    return types


@router.post("", status_code=201, response_model=EcuOut)
def upload_ecu(
    services: ServicesDep,
    a2l: Annotated[UploadFile, File(description="The ECU's A2L (ASAM MCD-2 MC).")],
    values: Annotated[
        UploadFile | None, File(description="Current values: Intel HEX, S19, DCM or CDFX.")
    ] = None,
    name: Annotated[str | None, Form(max_length=200, json_schema_extra=name_schema)] = None,
) -> EcuOut:
    """Upload an A2L and, optionally, the ECU's values. Both are checked before anything is
    stored; names in a DCM or CDFX that the A2L lacks come back as ``notes``."""
    limit = services.settings.max_whole_bytes
    a2l_data = _read(a2l, "a2l", limit)
    values_data = None if values is None else _read(values, "values", limit)
    uploaded = services.ecus.upload(a2l_data, values=values_data, name=name, filename=a2l.filename)
    return EcuOut.uploaded(uploaded)


@router.get("", response_model=PageOut[EcuOut])
def list_ecus(services: ServicesDep, limit: Limit = 50, offset: Offset = 0) -> PageOut:
    page = services.ecus.list(limit=limit, offset=offset)
    return PageOut[EcuOut](
        items=[EcuOut.of(e) for e in page.items],
        total=page.total,
        limit=page.limit,
        offset=page.offset,
    )


@router.get("/{ecu_id}", response_model=EcuOut)
def get_ecu(services: ServicesDep, ecu_id: Id) -> EcuOut:
    return EcuOut.of(services.ecus.get(ecu_id))


@router.delete("/{ecu_id}", status_code=204, response_class=Response)
def delete_ecu(services: ServicesDep, ecu_id: Id) -> Response:
    """Delete an ECU (runs linked to it keep their maps; their CDFX and image exports go)."""
    services.ecus.delete(ecu_id)
    return Response(status_code=204)


@router.put("/{ecu_id}/values", response_model=EcuOut)
def put_values(
    services: ServicesDep,
    ecu_id: Id,
    values: Annotated[UploadFile, File(description="Intel HEX, S19, DCM or CDFX.")],
) -> EcuOut:
    """Replace the ECU's values file (checked against its A2L first)."""
    services.ecus.get(ecu_id)
    data = _read(values, "values", services.settings.max_whole_bytes)
    return EcuOut.uploaded(services.ecus.set_values(ecu_id, data))


@router.get("/{ecu_id}/maps", response_model=MapsOut)
def list_maps(
    services: ServicesDep,
    ecu_id: Id,
    q: Annotated[str, Query(max_length=200, description="Part of a name or description.")] = "",
    type: Annotated[
        str | None,
        Query(
            max_length=100,
            pattern=TYPES_PATTERN,
            description="Comma-separated: MAP, CURVE, VAL_BLK, VALUE.",
        ),
    ] = None,
    limit: Limit = 100,
    offset: Offset = 0,
) -> MapsOut:
    """The A2L's characteristics, searched by name and description (case-insensitive)."""
    total, items = services.ecus.maps(
        ecu_id, query=q, types=_types(type), limit=limit, offset=offset
    )
    return MapsOut(items=items, total=total, limit=limit, offset=offset)  # type: ignore[arg-type]


@router.get("/{ecu_id}/maps/{name}", response_model=MapOut)
def get_map(services: ServicesDep, ecu_id: Id, name: str) -> MapOut:
    """A characteristic with its current values, decoded from the ECU's values file."""
    return MapOut.model_validate(services.ecus.map(ecu_id, name))


@router.get("/{ecu_id}/maps/{name}/template", response_model=TemplateOut)
def get_template(
    services: ServicesDep,
    ecu_id: Id,
    name: str,
    dataset_id: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None,
) -> TemplateOut:
    """New run from a MAP or CURVE: its table, units, limits and current values, the axes'
    input quantities matched to the dataset's channels (tool suffixes such as ``\\ETK:1``
    ignored)."""
    return TemplateOut.model_validate(services.ecus.template(ecu_id, name, dataset_id))


@router.post("/{ecu_id}/maps/{name}/base-map", status_code=201, response_model=BaseMapOut)
def create_base_map(services: ServicesDep, ecu_id: Id, name: str) -> BaseMapOut:
    """A base map ``<ECU>:<MAP>`` holding the map's current values."""
    return BaseMapOut.of(services.ecus.base_map(ecu_id, name))
