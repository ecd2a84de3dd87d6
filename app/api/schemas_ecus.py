"""Response bodies of the ECU endpoints (docs/rest-api.md#ecus, docs/calibration.md)."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from app.domain import Ecu
from app.services.ecus import Uploaded

Nested = list[Any]


class EcuOut(BaseModel):
    id: int
    name: str
    a2l_sha256: str
    values_format: str | None = Field(description="hex, s19, dcm, cdfx; null: no values file.")
    characteristics: int = Field(description="VALUE, CURVE, MAP and VAL_BLK objects of the A2L.")
    created_at: datetime
    notes: list[str] = Field(
        default_factory=list,
        description="What the upload check noticed without refusing it (names in a DCM or "
        "CDFX that the A2L does not know). Only on the upload's response.",
    )

    @classmethod
    def of(cls, e: Ecu, notes: list[str] | None = None) -> EcuOut:
        return cls(
            id=e.id,
            name=e.name,
            a2l_sha256=e.a2l_sha256,
            values_format=e.values_format,
            characteristics=e.characteristics,
            created_at=e.created_at,
            notes=notes or [],
        )

    @classmethod
    def uploaded(cls, u: Uploaded) -> EcuOut:
        return cls.of(u.ecu, u.notes)


class CompuMethodOut(BaseModel):
    model_config = ConfigDict(extra="allow")

    name: str
    kind: str
    unit: str
    format: str


class AxisDescrOut(BaseModel):
    model_config = ConfigDict(extra="allow")

    attribute: str = Field(description="STD_AXIS, FIX_AXIS, COM_AXIS, RES_AXIS, CURVE_AXIS.")
    input_quantity: str
    unit: str
    points: int
    limits: list[float]
    values: list[float] | None = Field(description="FIX_AXIS values; null for other axes.")


class CharacteristicOut(BaseModel):
    """A CHARACTERISTIC of the A2L (VALUE, CURVE, MAP, VAL_BLK)."""

    model_config = ConfigDict(extra="allow")

    name: str
    description: str
    type: str
    unit: str
    datatype: str
    limits: list[float]
    compu_method: CompuMethodOut
    record_layout: str
    address: int
    byte_order: str
    shape: list[int]
    axes: list[AxisDescrOut]


class MapsOut(BaseModel):
    items: list[CharacteristicOut]
    total: int
    limit: int
    offset: int


class ValuesOut(BaseModel):
    """A characteristic's current values, physical: axis points per axis, values nested in
    axis order (``values[i_x][i_y]``), a number for a VALUE."""

    axes: list[list[float | None]]
    values: Nested | float | None
    unit: str
    axis_units: list[str]


class MapOut(CharacteristicOut):
    values: ValuesOut | None = Field(description="null when the ECU has no values file.")


class TemplateAxisOut(BaseModel):
    name: str = Field(description="The matched dataset channel, else the input quantity.")
    quantity: str = Field(description="The A2L input quantity.")
    breakpoints: list[float | None] | None = Field(
        description="From the values file, else FIX_AXIS; null when neither says."
    )
    unit: str


class TemplateTableOut(BaseModel):
    axes: list[TemplateAxisOut]
    output_unit: str
    limits: list[float]


class ChannelMatchOut(BaseModel):
    matched: dict[str, str] = Field(description="Input quantity → dataset channel.")
    unmatched: list[str] = Field(description="Input quantities no channel matched.")


class CalibrationLinkOut(BaseModel):
    ecu_id: int
    map: str


class TemplateOut(BaseModel):
    """New run, filled in from an A2L map (docs/calibration.md#rest-and-cli)."""

    table: TemplateTableOut
    output: str | None = Field(
        description="A channel named like the map, else null: the A2L does not name the "
        "measured output, the user chooses it."
    )
    base_map: ValuesOut | None
    channels: ChannelMatchOut
    calibration: CalibrationLinkOut
