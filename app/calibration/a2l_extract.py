"""Parse one A2L with pya2ldb and write its summary: the child process of the A2L import.

Run as ``python -m app.calibration.a2l_extract IN.a2l OUT_DIR ENCODING``. pya2ldb's C++
parser writes ``OUT_DIR/<stem>.a2ldb`` (SQLite); this module reads the CHARACTERISTICs,
AXIS_PTS, RECORD_LAYOUTs and COMPU_METHODs out of it into :mod:`app.calibration.model`
objects and writes ``OUT_DIR/summary.json`` (:mod:`app.calibration.summary`), or
``OUT_DIR/error.json`` ``{"message": ...}`` when the file is no A2L.

It runs in a child process because pya2ldb prints to the terminal from C++, installs a
global ``rich`` traceback hook on import and holds the whole file in memory: none of that
belongs in the service. See ``docs/calibration.md#a2l-import``.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

from app.calibration.model import (
    CHARACTERISTIC_TYPES,
    IDENTICAL,
    AxisDescr,
    AxisPts,
    Characteristic,
    CompuMethod,
    LayoutItem,
    RecordLayout,
)
from app.calibration.summary import Summary, to_json

AXES = ("X", "Y", "Z", "4", "5")
#: RECORD_LAYOUT items that hold one value of their datatype, per axis.
_AXIS_ITEMS = ("NO_AXIS_PTS", "NO_RESCALE", "SRC_ADDR", "RIP_ADDR", "OFFSET", "SHIFT_OP", "DIST_OP")
_ALIGNMENTS = {
    "BYTE": "alignment_byte",
    "WORD": "alignment_word",
    "LONG": "alignment_long",
    "INT64": "alignment_int64",
    "FLOAT16_IEEE": "alignment_float16_ieee",
    "FLOAT32_IEEE": "alignment_float32_ieee",
    "FLOAT64_IEEE": "alignment_float64_ieee",
}
_RESERVED_TYPES = {"BYTE": "UBYTE", "WORD": "UWORD", "LONG": "ULONG", "LONG64": "A_UINT64"}
_BYTE_ORDERS = {"LITTLE_ENDIAN": "MSB_LAST", "BIG_ENDIAN": "MSB_FIRST"}


class NotAnA2lError(Exception):
    """The file parsed to nothing an A2L must hold."""


def extract(session: Any, model: Any) -> Summary:
    """Read the summary out of a pya2ldb session (``model`` is ``pya2l.model``)."""
    modules = session.query(model.Module).all()
    if not modules:
        raise NotAnA2lError("no '/begin MODULE' found: this is not an A2L (ASAM MCD-2 MC) file")
    extractor = _Extractor(session, model, modules[0])
    return extractor.summary(_characteristics(session, model), modules)


def _characteristics(session: Any, model: Any) -> list[Any]:
    """All CHARACTERISTIC rows with what :class:`_Extractor` reads of them loaded in a
    handful of ``IN`` queries (lazy loading costs one query per row and relation)."""
    from sqlalchemy.orm import selectinload

    c, ax = model.Characteristic, model.AxisDescr
    axis = selectinload(c.axis_descr)
    options = [
        selectinload(getattr(c, name))
        for name in (
            "byte_order",
            "number",
            "matrix_dim",
            "phys_unit",
            "bit_mask",
            "extended_limits",
            "ecu_address_extension",
            "display_identifier",
        )
    ]
    options += [
        axis.selectinload(getattr(ax, name))
        for name in (
            "axis_pts_ref",
            "curve_axis_ref",
            "fix_axis_par",
            "fix_axis_par_dist",
            "fix_axis_par_list",
            "deposit",
            "phys_unit",
        )
    ]
    return session.query(c).options(*options).order_by(c.rid).all()


class _Extractor:
    """Builds model objects, each COMPU_METHOD and RECORD_LAYOUT once."""

    def __init__(self, session: Any, model: Any, module: Any) -> None:
        self.session = session
        self.model = model
        common = module.mod_common
        self.byte_order = _byte_order(common.byte_order if common else None) or "MSB_LAST"
        self.deposit = common.deposit.mode if common and common.deposit else "ABSOLUTE"
        self.alignment = _alignment(common, ())
        self.methods: dict[str, CompuMethod] = {}
        self.layouts: dict[str, RecordLayout] = {}
        self.axis_pts: dict[str, AxisPts] = {}
        self.curves: dict[str, Any] = {}

    def summary(self, characteristics: list[Any], modules: list[Any]) -> Summary:
        skipped: dict[str, int] = {}
        chars = []
        self.curves = {c.name: c for c in characteristics if c.type == "CURVE"}
        for row in modules:
            for pts in row.axis_pts:
                self.axis_pts.setdefault(pts.name, self._axis_pts(pts))
        for row in characteristics:
            if row.type in CHARACTERISTIC_TYPES:
                chars.append(self._characteristic(row))
            else:
                skipped[row.type] = skipped.get(row.type, 0) + 1
        return Summary(
            module=modules[0].name, characteristics=chars, axis_pts=self.axis_pts, skipped=skipped
        )

    def _characteristic(self, row: Any) -> Characteristic:
        layout = self.layout(row.deposit)
        axes = tuple(self._axis(ax) for ax in row.axis_descr)
        fnc = layout.fnc_values
        number = row.number.number if row.number else None
        limits = row.extended_limits
        return Characteristic(
            name=row.name,
            description=row.longIdentifier or "",
            type=row.type,
            address=int(row.address),
            record_layout=layout,
            compu_method=self.method(row.conversion),
            lower=float(row.lowerLimit),
            upper=float(row.upperLimit),
            datatype=fnc.datatype if fnc else "",
            byte_order=_byte_order(row.byte_order) or self.byte_order,
            axes=axes,
            number=number,
            shape=_shape(row, axes, number),
            phys_unit=row.phys_unit.unit if row.phys_unit else "",
            bit_mask=row.bit_mask.mask if row.bit_mask else None,
            extended_limits=(limits.lowerLimit, limits.upperLimit) if limits else None,
            ecu_address_extension=row.ecu_address_extension.extension
            if row.ecu_address_extension
            else 0,
            display_identifier=row.display_identifier.display_name
            if row.display_identifier
            else "",
        )

    def _axis(self, row: Any) -> AxisDescr:
        pts_ref = row.axis_pts_ref.axisPoints if row.axis_pts_ref else None
        curve_ref = row.curve_axis_ref.curveAxis if row.curve_axis_ref else None
        method = self._axis_method(row.conversion, pts_ref, curve_ref)
        unit = row.phys_unit.unit if row.phys_unit else method.unit
        return AxisDescr(
            attribute=row.attribute,
            input_quantity=row.inputQuantity or "",
            unit=unit,
            compu_method=method,
            max_axis_points=int(row.maxAxisPoints),
            lower=float(row.lowerLimit),
            upper=float(row.upperLimit),
            fix_axis_values=_fix_axis_values(row, method),
            axis_pts_ref=pts_ref,
            curve_axis_ref=curve_ref,
            deposit=row.deposit.mode if row.deposit else self.deposit,
        )

    def _axis_method(self, name: str, pts_ref: str | None, curve_ref: str | None) -> CompuMethod:
        """The axis' own conversion; a COM_AXIS/CURVE_AXIS without one uses the referenced
        object's (ASAM: a CURVE_AXIS carries ``NO_COMPU_METHOD``)."""
        if name != IDENTICAL.name:
            return self.method(name)
        if pts_ref in self.axis_pts:
            return self.axis_pts[pts_ref].compu_method
        curve = self.curves.get(curve_ref or "")
        if curve is not None and curve.axis_descr:
            return self.method(curve.axis_descr[0].conversion)
        return IDENTICAL

    def _axis_pts(self, row: Any) -> AxisPts:
        layout = self.layout(row.depositAttr)
        x = layout.axis_pts("X") or layout.item("AXIS_RESCALE_X")
        method = self.method(row.conversion)
        return AxisPts(
            name=row.name,
            address=int(row.address),
            input_quantity=row.inputQuantity or "",
            record_layout=layout,
            compu_method=method,
            max_points=int(row.maxAxisPoints),
            lower=float(row.lowerLimit),
            upper=float(row.upperLimit),
            byte_order=_byte_order(row.byte_order) or self.byte_order,
            description=row.longIdentifier or "",
            datatype=x.datatype if x else "",
            deposit=row.deposit.mode if row.deposit else self.deposit,
            ecu_address_extension=row.ecu_address_extension.extension
            if row.ecu_address_extension
            else 0,
        )

    def method(self, name: str | None) -> CompuMethod:
        name = name or IDENTICAL.name
        if name not in self.methods:
            self.methods[name] = self._compu_method(name)
        return self.methods[name]

    def _compu_method(self, name: str) -> CompuMethod:
        if name == IDENTICAL.name:
            return IDENTICAL
        m = self.model
        row = self.session.query(m.CompuMethod).filter(m.CompuMethod.name == name).first()
        if row is None:
            return CompuMethod(name=name, kind="UNDEFINED")
        kind = row.conversionType
        base: dict[str, Any] = {
            "name": name,
            "kind": kind,
            "unit": row.unit or "",
            "format": row.format or "",
        }
        if kind == "LINEAR" and row.coeffs_linear:
            base["coeffs"] = (row.coeffs_linear.a, row.coeffs_linear.b)
        elif kind == "RAT_FUNC" and row.coeffs:
            c = row.coeffs
            base["coeffs"] = (c.a, c.b, c.c, c.d, c.e, c.f)
        elif kind == "FORM" and row.formula:
            base["formula"] = row.formula.f_x or ""
            base["formula_inv"] = row.formula.formula_inv.g_x if row.formula.formula_inv else ""
        elif kind in ("TAB_INTP", "TAB_NOINTP", "TAB_VERB") and row.compu_tab_ref:
            base.update(self._table(row.compu_tab_ref.conversionTable))
        return CompuMethod(**base)

    def _table(self, name: str) -> dict[str, Any]:
        """COMPU_TAB pairs, or COMPU_VTAB / COMPU_VTAB_RANGE entries, named ``name``. A
        COMPU_TAB's own TAB_INTP/TAB_NOINTP decides interpolation (the demo's
        ``CM.TAB_NOINTP.*`` methods say TAB_INTP but reference TAB_NOINTP tables)."""
        m = self.model
        tab = self.session.query(m.CompuTab).filter(m.CompuTab.name == name).first()
        if tab is not None:
            default = tab.default_value_numeric.display_value if tab.default_value_numeric else None
            pairs = tuple(
                (float(p.inVal), float(p.outVal)) for p in sorted(tab.pairs, key=_position)
            )
            kind = tab.conversionType if tab.conversionType in ("TAB_INTP", "TAB_NOINTP") else None
            return {"table": pairs, "default_value": default, **({"kind": kind} if kind else {})}
        vtab = self.session.query(m.CompuVtab).filter(m.CompuVtab.name == name).first()
        if vtab is not None:
            pairs = tuple(
                (float(p.inVal), str(p.outVal)) for p in sorted(vtab.pairs, key=_position)
            )
            return {"verbal": pairs, "default_text": _default_text(vtab)}
        ranges = self.session.query(m.CompuVtabRange).filter(m.CompuVtabRange.name == name).first()
        if ranges is not None:
            triples = tuple(
                (float(t.inValMin), float(t.inValMax), str(t.outVal))
                for t in sorted(ranges.triples, key=_position)
            )
            return {"verbal_ranges": triples, "default_text": _default_text(ranges)}
        return {}

    def layout(self, name: str | None) -> RecordLayout:
        name = name or ""
        if name not in self.layouts:
            m = self.model
            row = self.session.query(m.RecordLayout).filter(m.RecordLayout.name == name).first()
            self.layouts[name] = (
                RecordLayout(name=name, alignment=self.alignment, defined=False)
                if row is None
                else self._record_layout(row)
            )
        return self.layouts[name]

    def _record_layout(self, row: Any) -> RecordLayout:
        items: list[LayoutItem] = []
        fixed: list[tuple[str, int]] = []
        if row.fnc_values:
            f = row.fnc_values
            items.append(
                LayoutItem(
                    "FNC_VALUES", f.position, f.datatype, f.indexMode or "", f.addresstype or ""
                )
            )
        if row.identification:
            items.append(
                LayoutItem(
                    "IDENTIFICATION", row.identification.position, row.identification.datatype
                )
            )
        if row.rip_addr_w:
            items.append(LayoutItem("RIP_ADDR_W", row.rip_addr_w.position, row.rip_addr_w.datatype))
        for axis in AXES:
            suffix = axis.lower()
            for keyword in ("AXIS_PTS", "AXIS_RESCALE"):
                entry = getattr(row, f"{keyword.lower()}_{suffix}")
                if entry is not None:
                    kind = f"{keyword}_{axis}"
                    items.append(
                        LayoutItem(
                            kind, entry.position, entry.datatype, entry.indexIncr, entry.addressing
                        )
                    )
            for keyword in _AXIS_ITEMS:
                entry = getattr(row, f"{keyword.lower()}_{suffix}")
                if entry is not None:
                    items.append(LayoutItem(f"{keyword}_{axis}", entry.position, entry.datatype))
            fix = getattr(row, f"fix_no_axis_pts_{suffix}")
            if fix is not None:
                fixed.append((axis, int(fix.numberOfAxisPoints)))
        for reserved in row.reserved or ():
            items.append(
                LayoutItem(
                    "RESERVED", reserved.position, _RESERVED_TYPES.get(reserved.dataSize, "UBYTE")
                )
            )
        return RecordLayout(
            name=row.name,
            items=tuple(sorted(items, key=lambda item: item.position)),
            fix_no_axis_pts=tuple(fixed),
            alignment=_alignment(row, self.alignment),
            static_record_layout=bool(row.static_record_layout),
            static_address_offsets=bool(row.static_address_offsets),
        )


def _position(entry: Any) -> int:
    return entry.position or 0


def _default_text(table: Any) -> str | None:
    return table.default_value.display_string if table.default_value else None


def _byte_order(row: Any) -> str | None:
    if row is None or not row.byteOrder:
        return None
    return _BYTE_ORDERS.get(row.byteOrder, row.byteOrder)


def _alignment(row: Any, defaults: tuple[tuple[str, int], ...]) -> tuple[tuple[str, int], ...]:
    """``ALIGNMENT_*`` of ``row`` (a RECORD_LAYOUT or MOD_COMMON), falling back to ``defaults``."""
    merged = dict(defaults)
    for key, attr in _ALIGNMENTS.items():
        entry = getattr(row, attr, None) if row is not None else None
        if entry is not None:
            merged[key] = int(entry.alignmentBorder)
    return tuple(merged.items())


def _fix_axis_values(row: Any, method: CompuMethod) -> tuple[float, ...] | None:
    """Axis values of a FIX_AXIS (ASAM MCD-2 MC: ``FIX_AXIS_PAR``: x_i = offset + i·2^shift;
    ``FIX_AXIS_PAR_DIST``: x_i = offset + i·distance, i = 0…n−1, ECU-internal values
    converted with a linear conversion; ``FIX_AXIS_PAR_LIST``: the listed values)."""
    if row.fix_axis_par_list is not None and list(row.fix_axis_par_list.axisPts_Value):
        return tuple(float(v) for v in row.fix_axis_par_list.axisPts_Value)
    if row.fix_axis_par is not None and row.fix_axis_par.numberapo:
        p = row.fix_axis_par
        raw = [p.offset + i * 2.0**p.shift for i in range(p.numberapo)]
    elif row.fix_axis_par_dist is not None and row.fix_axis_par_dist.numberapo:
        p = row.fix_axis_par_dist
        raw = [p.offset + i * float(p.distance) for i in range(p.numberapo)]
    else:
        return None
    if method.kind == "LINEAR" and len(method.coeffs) == 2:
        a, b = method.coeffs
        return tuple(a * x + b for x in raw)
    return tuple(float(x) for x in raw)


def _shape(row: Any, axes: tuple[AxisDescr, ...], number: int | None) -> tuple[int, ...]:
    """Points per axis (CURVE/MAP), MATRIX_DIM or NUMBER (VAL_BLK), () for a VALUE."""
    if row.type == "VALUE":
        return ()
    if row.type in ("CURVE", "MAP"):
        return tuple(ax.points for ax in axes)
    dims = [int(n) for n in (row.matrix_dim.numbers if row.matrix_dim else ())]
    while len(dims) > 1 and dims[-1] == 1:
        dims.pop()
    if dims and math.prod(dims) > 0:
        return tuple(dims)
    return (number or 1,)


def main(argv: list[str]) -> int:
    source, out_dir, encoding = Path(argv[0]), Path(argv[1]), argv[2]
    try:
        import pya2l
        from pya2l import model

        session = pya2l.import_a2l(
            str(source),
            output_dir=str(out_dir),
            encoding=encoding,
            loglevel="ERROR",
            progress_bar=False,
        )
        summary = extract(session, model)
        session.close()
    except NotAnA2lError as exc:
        return _fail(out_dir, str(exc))
    except Exception as exc:  # pya2ldb raises RuntimeError/ValueError/... on syntax errors
        return _fail(out_dir, f"the A2L does not parse: {exc}")
    (out_dir / "summary.json").write_text(json.dumps(to_json(summary)), encoding="utf-8")
    return 0


def _fail(out_dir: Path, message: str) -> int:
    (out_dir / "error.json").write_text(json.dumps({"message": message}), encoding="utf-8")
    return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
