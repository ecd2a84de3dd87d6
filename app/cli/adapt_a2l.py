"""``mapwise adapt --a2l FILE --map NAME [--values FILE]``: the table from an A2L map.

The map's axes are named after its input quantities and matched to the log's channels by
name, tool suffixes such as ``\\ETK:1`` or ``:1`` ignored (:mod:`app.calibration.matching`);
their points come from the values file (HEX, S19, DCM or CDFX), else from a FIX_AXIS, else
from ``--axis``. The values file's map is the starting map (θ0). The learned map can then
be written as DCM and CDFX keyed by the A2L name and as a patched memory image, the values
as the ECU stores them (docs/calibration.md#rest-and-cli, docs/cli.md#adapt).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.cli.a2l import open_a2l_file, read_file
from app.cli.errors import UsageError

if TYPE_CHECKING:
    from app.calibration.a2l import A2lFile
    from app.calibration.model import Characteristic
    from app.calibration.values import CalibrationValues
    from estimation.table import Table

CALIBRATION_FLAGS = ("map", "values", "out_dcm", "out_cdfx", "out_image")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--a2l", type=Path, metavar="FILE", help="the ECU's A2L: the table is --map")
    p.add_argument("--map", metavar="NAME", help="the A2L MAP or CURVE to adapt")
    p.add_argument(
        "--values", type=Path, metavar="FILE", help="current values: .hex, .s19, .dcm or .cdfx"
    )
    p.add_argument("--out-dcm", type=Path, metavar="F.dcm", help="write the map as DCM")
    p.add_argument("--out-cdfx", type=Path, metavar="F.cdfx", help="write the map as CDFX")
    p.add_argument(
        "--out-image", type=Path, metavar="F", help="write the --values image with the map patched"
    )


def check_flags(args: argparse.Namespace) -> None:
    """The calibration flags need ``--a2l`` (and ``--a2l`` needs ``--map``)."""
    if args.a2l is None:
        for key in CALIBRATION_FLAGS:
            if getattr(args, key) is not None:
                raise UsageError(f"--{key.replace('_', '-')} needs --a2l FILE")
        return
    if args.map is None:
        raise UsageError("--a2l needs --map NAME (`mapwise a2l list FILE` lists the maps)")
    if args.out_image is not None and args.values is None:
        raise UsageError("--out-image needs --values with the ECU's HEX or S19 image")


@dataclass
class A2lTarget:
    """The A2L map a run adapts, its current values and the run's table from them."""

    a2l: A2lFile
    char: Characteristic
    values: CalibrationValues | None
    values_format: str | None
    values_data: bytes | None
    axes: list[tuple[str, list[float]]]
    output: str


def resolve(
    args: argparse.Namespace, channels: list[str], axes: list[tuple[str, list[float]]] | None
) -> A2lTarget:
    """The map of ``--a2l``/``--map``, its values, and the table's axes over the log's
    ``channels`` (``axes`` from ``--axis`` win); exit 2 listing unmatched quantities."""
    from app.calibration.matching import match_channels
    from app.calibration.values import detect_values_format, read_values
    from app.services.calibration_runs import check_table
    from app.services.ecus import IMAGE_FORMATS, require_table

    a2l = open_a2l_file(args.a2l)
    char = require_table(a2l.get(args.map), field="--map")
    values = fmt = data = None
    if args.values is not None:
        data = read_file(args.values, "--values")
        fmt = detect_values_format(data)
        values = read_values(a2l, char, data)
    if args.out_image is not None and fmt not in IMAGE_FORMATS:
        raise UsageError(f"--out-image needs a HEX or S19 image as --values, not a {fmt} file")
    if axes is None:
        axes = _axes_from_a2l(char, values, channels, match_channels)
    check_table(char, {"axes": [{"breakpoints": b} for _, b in axes]}, "the table")
    output = args.y or match_channels([char.name], channels).matched.get(char.name)
    if output is None:
        raise UsageError(
            f"the following arguments are required: --y (the A2L does not name the measured "
            f"output of {char.name})"
        )
    return A2lTarget(a2l, char, values, fmt, data, axes, output)


def _axes_from_a2l(
    char: Characteristic, values: CalibrationValues | None, channels: list[str], match: Any
) -> list[tuple[str, list[float]]]:
    quantities = [a.input_quantity for a in char.axes]
    found = match(quantities, channels)
    if found.unmatched:
        raise UsageError(
            f"no channel of the log matches the input quantit"
            f"{'y' if len(found.unmatched) == 1 else 'ies'} of {char.name}: "
            f"{', '.join(found.unmatched)} (tool suffixes such as \\ETK:1 are ignored); "
            "name the axes with --axis CHANNEL=B1,B2,..."
        )
    axes = []
    for i, axis in enumerate(char.axes):
        if values is not None:
            points = [float(x) for x in np.asarray(values.axes[i], dtype=np.float64)]
        elif axis.fix_axis_values is not None:
            points = [float(x) for x in axis.fix_axis_values]
        else:
            raise UsageError(
                f"{char.name}: the points of axis {i} ({axis.input_quantity}, {axis.attribute}) "
                "are in the ECU's values: give --values FILE or --axis"
            )
        axes.append((found.matched[axis.input_quantity], points))
    return axes


def theta0(target: A2lTarget) -> list[Any] | None:
    """The values file's map as the starting map when its grid is the table's."""
    if target.values is None:
        return None
    values = np.asarray(target.values.values, dtype=np.float64)
    shape = tuple(len(b) for _, b in target.axes)
    if values.shape != shape or not np.all(np.isfinite(values)):
        return None
    return values.tolist()


def write_outputs(args: argparse.Namespace, target: A2lTarget, table: Table) -> dict[str, Any]:
    """Write ``--out-dcm/--out-cdfx/--out-image``; return what the JSON document gains."""
    from app.services import calibration_runs as cal

    char = target.char
    description = f"mapwise adapt ({args.estimator}) of {char.name}"
    outputs: list[tuple[Path | None, Any]] = [
        (args.out_dcm, lambda: cal.dcm_text(char, table, description=description).encode()),
        (args.out_cdfx, lambda: cal.cdfx_bytes(char, table)),
        (
            args.out_image,
            lambda: cal.patched_image(target.a2l, char, table, target.values_data or b""),
        ),
    ]
    for path, content in outputs:
        if path is not None:
            _write(path, content())
    return cal.json_extras(char, table, {"a2l": args.a2l.name})


def _write(path: Path, content: bytes) -> None:
    try:
        path.write_bytes(content)
    except OSError as exc:
        raise UsageError(f"{path}: {exc.strerror}") from None
