"""Load the regulatory cycles shipped in ``estimation/cycles/data`` (see ``data/SOURCES.md``).

Files are read through :mod:`importlib.resources`, so they work from an installed wheel.
Every cycle is returned on a 1 Hz time base starting at ``t = 0``:

- ``udds``, ``hwfet``, ``us06``, ``wltc3b``: FASTSim CSV ``cycSecs,cycMps,cycGrade,…`` (m/s,
  grade as rise/run) → ``speed_kmh = 3.6·cycMps``, ``grade_pct = 100·cycGrade``.
- ``nedc``: 1180 whitespace-separated km/h values for t = 0…1179 s. The regulation's cycle
  lasts 1180 s and ends at standstill, so the final standstill sample at t = 1180 s is appended.
- ``whtc``: ``Time Speed Torque`` in %, t = 1…1800 s, motoring points written ``m``
  (→ ``torque_pct = −100``, full drag). The idle point at t = 0 s (0 %, 0 %) is prepended so
  the cycle spans the regulation's 1800 s.
- ``ftp75``: UDDS (0…1369 s) followed by the UDDS's first 505 s (bag 3) at t = 1370…1874 s.
  The UDDS sample at its own t = 0 (standstill) coincides with the UDDS end (standstill), so
  the appended part starts at UDDS t = 1 s; the 10-min hot soak is not on the time line.
- ``sdmp``: synthetic, see :func:`estimation.cycles.synthetic.make_sdmp` (seed 0).
"""

from __future__ import annotations

import io
from importlib import resources

import numpy as np

from estimation.cycles.base import Cycle
from estimation.cycles.synthetic import make_sdmp
from estimation.errors import ConfigError

_FASTSIM_FILES = {
    "udds": ("udds.csv", "EPA UDDS (FTP-72)"),
    "hwfet": ("hwfet.csv", "EPA HWFET"),
    "us06": ("us06.csv", "EPA US06"),
    "wltc3b": ("wltc_3b.csv", "WLTC class 3b (UN GTR 15)"),
}
_FASTSIM_NOTE = "EPA/UN schedule, public domain; file from NREL FASTSim 2.x (Apache-2.0)"
_FTP75_BAG3_S = 505
_CYCLE_NAMES = ("udds", "hwfet", "us06", "wltc3b", "nedc", "ftp75", "whtc", "sdmp")


def list_cycles() -> list[str]:
    """Names accepted by :func:`load_cycle`."""
    return list(_CYCLE_NAMES)


def load_cycle(name: str) -> Cycle:
    """Load cycle ``name`` (one of :func:`list_cycles`, case-insensitive).

    Raises :class:`~estimation.errors.ConfigError` (a ``ValueError``) for an unknown name.

    >>> c = load_cycle("ftp75")
    >>> c.kind, c.duration_s
    ('vehicle', 1874.0)
    """
    key = str(name).strip().lower()
    if key in _FASTSIM_FILES:
        return _load_fastsim(key)
    if key == "nedc":
        return _load_nedc()
    if key == "whtc":
        return _load_whtc()
    if key == "ftp75":
        return _ftp75()
    if key == "sdmp":
        return make_sdmp()
    raise ConfigError(f"unknown cycle {name!r}; valid names: {', '.join(_CYCLE_NAMES)}")


def _read(filename: str) -> str:
    return (resources.files("estimation.cycles") / "data" / filename).read_text(
        encoding="utf-8-sig"  # wltc_3b.csv starts with a BOM
    )


def _load_fastsim(key: str) -> Cycle:
    filename, title = _FASTSIM_FILES[key]
    table = np.loadtxt(io.StringIO(_read(filename)), delimiter=",", skiprows=1, ndmin=2)
    return Cycle(
        name=key,
        kind="vehicle",
        time_s=table[:, 0],
        speed_kmh=3.6 * table[:, 1],
        grade_pct=100.0 * table[:, 2],
        source=f"{title}; {_FASTSIM_NOTE}; data/{filename}",
    )


def _load_nedc() -> Cycle:
    speed_kmh = np.array(_read("nedc.txt").split(), dtype=np.float64)
    speed_kmh = np.append(speed_kmh, 0.0)  # regulation end point t = 1180 s, standstill
    return Cycle(
        name="nedc",
        kind="vehicle",
        time_s=np.arange(speed_kmh.size, dtype=np.float64),
        speed_kmh=speed_kmh,
        source="NEDC, UNECE R83 / Directive 70/220/EEC (ECE-15 x4 + EUDC); data/nedc.txt "
        "(t = 0..1179 s) plus the standstill end point at 1180 s",
    )


def _load_whtc() -> Cycle:
    lines = _read("whtc.txt").split("\n")
    rows = [line.split() for line in lines[2:] if line.strip()]  # skip names and units
    time_s = np.array([float(r[0]) for r in rows])
    speed_pct = np.array([float(r[1]) for r in rows])
    torque_pct = np.array([-100.0 if r[2] == "m" else float(r[2]) for r in rows])
    return Cycle(
        name="whtc",
        kind="engine",
        time_s=np.concatenate(([0.0], time_s)),
        speed_pct=np.concatenate(([0.0], speed_pct)),
        torque_pct=np.concatenate(([0.0], torque_pct)),
        source="WHTC, UN GTR No. 4 Annex 1; data/whtc.txt (t = 1..1800 s) plus the idle "
        "point at t = 0 s; motoring 'm' -> torque_pct = -100 (full drag)",
    )


def _ftp75() -> Cycle:
    udds = _load_fastsim("udds")
    bag3 = slice(1, _FTP75_BAG3_S + 1)
    t_end = udds.time_s[-1]
    assert udds.grade_pct is not None
    return Cycle(
        name="ftp75",
        kind="vehicle",
        time_s=np.concatenate((udds.time_s, t_end + udds.time_s[bag3])),
        speed_kmh=np.concatenate((udds.speed_kmh, udds.speed_kmh[bag3])),
        grade_pct=np.concatenate((udds.grade_pct, udds.grade_pct[bag3])),
        source="EPA FTP-75 = UDDS (0..1369 s) + UDDS 0..505 s (bag 3, hot start) without the "
        f"hot soak; {_FASTSIM_NOTE}; data/udds.csv",
    )
