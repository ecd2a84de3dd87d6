"""Base maps: promote a run's version, import a map file, list, get."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request

from app.api.deps import MAX_ID, Id, ServicesDep
from app.api.schemas import ERRORS, BaseMapOut, PageOut, PromoteIn
from app.errors import InvalidRequestError, MalformedRequestError, PayloadTooLargeError
from app.services.base_map_edits import edited_map

router = APIRouter(prefix="/base-maps", tags=["base maps"], responses=ERRORS)

_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": PromoteIn.model_json_schema()},
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["file"],
                    "additionalProperties": False,  # the form parser takes at most 4 fields
                    "properties": {
                        "file": {"type": "string", "format": "binary"},
                        "name": {"type": "string", "maxLength": 200},
                    },
                }
            },
        },
    }
}


@router.post("", status_code=201, response_model=BaseMapOut, openapi_extra=_BODY)
async def create_base_map(request: Request, services: ServicesDep) -> BaseMapOut:
    """JSON ``{run_id, version_id, name}`` promotes a run's map version (with ``values`` and
    ``edits``, source "edit": an edited copy of it); multipart ``file``
    (JSON / CSV / DCM map) + ``name`` imports one."""
    from starlette.concurrency import run_in_threadpool

    content_type = request.headers.get("content-type", "")
    if content_type.startswith("multipart/form-data"):
        form = await request.form(max_files=1, max_fields=4)
        upload = form.get("file")
        if upload is None or isinstance(upload, str):
            raise InvalidRequestError("a map file is required", field="file")
        limit = services.settings.max_map_file_bytes
        data = await upload.read(limit + 1)  # never more: it is parsed whole
        if len(data) > limit:
            size = f"{upload.size:,} bytes" if upload.size is not None else "larger"
            raise PayloadTooLargeError(
                f"the map file is {size}; a map of at most {services.settings.max_cells:,} "
                f"cells (MAPWISE_MAX_CELLS) takes at most {limit:,} bytes",
                field="file",
            )
        name = form.get("name")
        base_map = await run_in_threadpool(
            services.base_maps.import_file,
            data,
            name=name if isinstance(name, str) else None,
            filename=upload.filename,
        )
        return BaseMapOut.of(base_map)
    try:
        body = PromoteIn.model_validate_json(await request.body())
    except ValueError as exc:
        errors = getattr(exc, "errors", lambda: [])()
        loc = errors[0]["loc"] if errors else ()
        field = ".".join(str(p) for p in loc) or None
        message = errors[0]["msg"] if errors else str(exc)
        if errors and errors[0].get("type") == "json_invalid":
            raise MalformedRequestError(f"body is not valid JSON: {message}") from None
        raise InvalidRequestError(f"{field or 'body'}: {message}", field=field) from None
    base_map = await run_in_threadpool(
        services.base_maps.promote,
        run_id=body.run_id,
        version_id=body.version_id,
        name=body.name,
        edited=edited_map(body.values, body.edits, body.source),
    )
    return BaseMapOut.of(base_map)


@router.get("", response_model=PageOut[BaseMapOut])
def list_base_maps(
    services: ServicesDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> PageOut:
    page = services.base_maps.list(limit=limit, offset=offset)
    return PageOut[BaseMapOut](
        items=[BaseMapOut.of(b) for b in page.items],
        total=page.total,
        limit=page.limit,
        offset=page.offset,
    )


@router.get("/{base_map_id}", response_model=BaseMapOut)
def get_base_map(services: ServicesDep, base_map_id: Id) -> BaseMapOut:
    return BaseMapOut.of(services.base_maps.get(base_map_id))
