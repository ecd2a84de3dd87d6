"""A multi-rate measurement file as the calibration tools write it, built with asammdf:
three channel groups (1 kHz, 10 ms, 100 ms), a value-table (enumeration) channel, a
rational conversion with a pole (±inf), an integer status byte, a boolean, a 16-bit integer
and a float channel with NaN, +inf and (MDF4) an invalid sample, named as INCA names them."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

T1 = np.arange(0.0, 2.0, 0.001)  # 1 kHz
T10 = np.arange(0.005, 2.0, 0.01)  # 10 ms
T100 = np.arange(0.02, 1.95, 0.1)  # 100 ms
SPAN = (0.02, float(T100[-1]))  # what every group covers: the 100 ms group's first…last

FAST = np.sin(2 * np.pi * 3 * T1)
MODE = (np.arange(T10.size) // 7 % 3).astype(np.uint8)  # 0=off, 1=idle, 2=run
MODE_TABLE = {"val_0": 0, "text_0": b"off", "val_1": 1, "text_1": b"idle", "val_2": 2}
MODE_TABLE |= {"text_2": b"run", "default": b"unknown"}
POLE_RAW = (np.arange(T10.size) % 20).astype(np.uint8)  # raw 10 is the pole
POLE = "ASAM.M.SCALAR.UBYTE.HYPERBOLIC"
POLE_CONVERSION = {"P1": 0, "P2": 0, "P3": -1, "P4": 0, "P5": 1, "P6": -10}  # -1/(x - 10)
STATUS = (np.arange(T10.size) // 13 % 5).astype(np.uint8) * 3
FLAG = (np.arange(T10.size) // 4) % 2 == 0
NMOT = "nmot_w\\ETK:1"
SPEED = 800 + 300 * T100**2
TEMP = (np.arange(T100.size) * 37 % 400).astype(np.int16)  # 16 bits: a quantity, not a state
LAMBDA = 1.0 + 0.01 * np.cos(T100)
LAMBDA_NAN, LAMBDA_INF = 3, 11
LAMBDA_INVALID = 7  # MDF4 only: MDF3 has no invalidation bits


def pole_physical() -> np.ndarray:
    """The rational conversion as asammdf applies it: ``-1 / (raw - 10)``, -inf at raw 10."""
    with np.errstate(divide="ignore"):
        return -1.0 / (POLE_RAW.astype(np.float64) - 10.0)


def lambda_values() -> np.ndarray:
    values = LAMBDA.copy()
    values[LAMBDA_NAN], values[LAMBDA_INF] = np.nan, np.inf
    return values


@dataclass(frozen=True, slots=True)
class Measurement:
    path: Path
    version: str

    @property
    def mdf4(self) -> bool:
        return self.version.startswith("4")

    def bytes(self) -> bytes:
        return self.path.read_bytes()


def write_measurement(directory: Path, version: str = "4.10") -> Measurement:
    """The measurement file, saved by asammdf as MDF ``version`` under ``directory``."""
    from asammdf import MDF, Signal

    mdf4 = version.startswith("4")
    invalid = np.zeros(T100.size, dtype=bool)
    invalid[LAMBDA_INVALID] = True
    mdf = MDF(version=version)
    mdf.append([Signal(FAST, T1, name="fast", unit="V")])
    mdf.append(
        [
            Signal(MODE, T10, name="mode", conversion=dict(MODE_TABLE)),
            Signal(POLE_RAW, T10, name=POLE, unit="1/s", conversion=dict(POLE_CONVERSION)),
            Signal(STATUS, T10, name="status"),
            Signal(FLAG, T10, name="flag"),
        ]
    )
    mdf.append(
        [
            Signal(SPEED, T100, name=NMOT, unit="1/min"),
            Signal(TEMP, T100, name="tmot", unit="degC"),
            Signal(
                lambda_values(),
                T100,
                name="lambda",
                invalidation_bits=invalid if mdf4 else None,
            ),
        ]
    )
    path = Path(mdf.save(directory / ("log" + (".mf4" if mdf4 else ".mdf")), overwrite=True))
    mdf.close()
    return Measurement(path, version)


def write_sparse_csv(directory: Path, measurement: Measurement, channels: list[str]) -> Path:
    """The measurement exported by asammdf as a sparse CSV: union of the groups'
    timestamps, each channel only on its own rows (empty cells elsewhere), raw enumeration
    values."""
    from asammdf import MDF

    with MDF(measurement.path) as mdf:
        frame = mdf.to_dataframe(
            channels=channels,
            use_interpolation=False,
            time_from_zero=False,
            ignore_value2text_conversions=True,
        )
    path = directory / "export.csv"
    frame.to_csv(path, float_format="%.17g")
    return path
