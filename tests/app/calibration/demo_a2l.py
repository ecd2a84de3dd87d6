"""The ASAM demo A2L from the pya2ldb wheel, and a completed copy of it for decoding tests.

``ASAP2_Demo_V161.a2l`` as shipped in the wheel is a stripped re-export: its
characteristics reference RECORD_LAYOUTs it never defines, its FIX_AXIS axes carry no
``FIX_AXIS_PAR*``, its COMPU_TABs announce value pairs they do not list, and its verbal
tables are COMPU_TABs of type TAB_VERB (pya2ldb rejects them). :func:`full_demo_text`
adds exactly what is missing, so values can be decoded with it (``docs/calibration.md#a2l-import``):

- RECORD_LAYOUTs after the ASAM demo's naming: ``RL.FNC.<T>.<dir>`` is ``FNC_VALUES 1 <T>
  <dir> DIRECT``; ``RL.CURVE.<F>.<A>.<INCR|DECR>`` is ``NO_AXIS_PTS_X 1 UBYTE``,
  ``AXIS_PTS_X 2 <A> INDEX_<..> DIRECT``, ``FNC_VALUES 3 <F> COLUMN_DIR DIRECT``;
  ``RL.MAP.<F>.<A>.<B>.INCR`` likewise with X and Y; ``RL.AXIS_PTS.<A>.<..>`` is
  ``NO_AXIS_PTS_X 1 UBYTE``, ``AXIS_PTS_X 2 <A> INDEX_<..> DIRECT``;
  ``Scalar_FLOAT64_IEEE`` is ``FNC_VALUES 1 FLOAT64_IEEE ROW_DIR DIRECT``.
- FIX_AXIS parameters: ``FIX_AXIS_PAR_DIST 0 20 6`` / ``FIX_AXIS_PAR 0 4 6`` /
  ``FIX_AXIS_PAR_LIST 2 5 9 12 17 23`` on the three ``ASAM.C.CURVE.FIX_AXIS.*`` curves
  (named after them) and ``FIX_AXIS_PAR_DIST 0 1 n`` on any other FIX_AXIS.
- COMPU_TAB pairs ``i → 10·i`` (i = 0…n−1); the TAB_VERB tables as COMPU_VTABs ``i →
  "state_i"``; COMPU_VTAB_RANGE triples ``[10·i, 10·i+9] → "range_i"``.
"""

from __future__ import annotations

import re
from importlib.util import find_spec
from pathlib import Path

# Located without importing pya2l: importing it registers a global SQLAlchemy "connect"
# listener (SQLite's create_function) that breaks every PostgreSQL engine of the process.
_SPEC = find_spec("pya2l")
assert _SPEC is not None
assert _SPEC.origin is not None
DEMO_A2L = Path(_SPEC.origin).parent / "examples" / "ASAP2_Demo_V161.a2l"

FIX_AXIS_PARAMETERS = {
    "ASAM.C.CURVE.FIX_AXIS.PAR_DIST": "FIX_AXIS_PAR_DIST 0 20 6",
    "ASAM.C.CURVE.FIX_AXIS.PAR": "FIX_AXIS_PAR 0 4 6",
    "ASAM.C.CURVE.FIX_AXIS.PAR_LIST": (
        "/begin FIX_AXIS_PAR_LIST 2 5 9 12 17 23 /end FIX_AXIS_PAR_LIST"
    ),
}
FIX_AXIS_VALUES = {
    "ASAM.C.CURVE.FIX_AXIS.PAR_DIST": (0.0, 20.0, 40.0, 60.0, 80.0, 100.0),
    "ASAM.C.CURVE.FIX_AXIS.PAR": (0.0, 16.0, 32.0, 48.0, 64.0, 80.0),
    "ASAM.C.CURVE.FIX_AXIS.PAR_LIST": (2.0, 5.0, 9.0, 12.0, 17.0, 23.0),
}

_FNC_TYPES = ("UBYTE", "SBYTE", "UWORD", "SWORD", "ULONG", "SLONG", "FLOAT32_IEEE", "FLOAT64_IEEE")
_RECORD_LAYOUTS = (
    *(f"RL.FNC.{t}.ROW_DIR\n  FNC_VALUES 1 {t} ROW_DIR DIRECT" for t in _FNC_TYPES),
    "RL.FNC.SWORD.COLUMN_DIR\n  FNC_VALUES 1 SWORD COLUMN_DIR DIRECT",
    "Scalar_FLOAT64_IEEE\n  FNC_VALUES 1 FLOAT64_IEEE ROW_DIR DIRECT",
    *(
        f"RL.CURVE.SWORD.SBYTE.{d}\n  NO_AXIS_PTS_X 1 UBYTE\n"
        f"  AXIS_PTS_X 2 SBYTE INDEX_{d} DIRECT\n  FNC_VALUES 3 SWORD COLUMN_DIR DIRECT"
        for d in ("INCR", "DECR")
    ),
    "RL.MAP.SWORD.SBYTE.SBYTE.INCR\n  NO_AXIS_PTS_X 1 UBYTE\n  NO_AXIS_PTS_Y 2 UBYTE\n"
    "  AXIS_PTS_X 3 SBYTE INDEX_INCR DIRECT\n  AXIS_PTS_Y 4 SBYTE INDEX_INCR DIRECT\n"
    "  FNC_VALUES 5 SWORD COLUMN_DIR DIRECT",
    "RL.AXIS_PTS.SBYTE.DECR\n  NO_AXIS_PTS_X 1 UBYTE\n  AXIS_PTS_X 2 SBYTE INDEX_DECR DIRECT",
    "RL.AXIS_PTS.RES_AXIS\n  NO_RESCALE_X 1 UBYTE\n  AXIS_RESCALE_X 2 UBYTE 5 INDEX_INCR DIRECT",
)


def demo_text() -> str:
    """The wheel's demo A2L, with LF line ends."""
    return DEMO_A2L.read_text(encoding="latin-1").replace("\r\n", "\n")


def full_demo_text() -> str:
    """The demo completed as described in the module docstring."""
    text = demo_text()
    layouts = "".join(
        f"    /begin RECORD_LAYOUT {body}\n    /end RECORD_LAYOUT\n" for body in _RECORD_LAYOUTS
    )
    text = text.replace("    /begin MOD_COMMON", layouts + "    /begin MOD_COMMON", 1)
    text = re.sub(
        r"/begin CHARACTERISTIC\s.*?/end CHARACTERISTIC",
        _with_fix_axis_parameters,
        text,
        flags=re.S,
    )
    text = re.sub(r"/begin COMPU_TAB\s.*?/end COMPU_TAB", _with_pairs, text, flags=re.S)
    text = re.sub(
        r"/begin COMPU_VTAB_RANGE\s.*?/end COMPU_VTAB_RANGE", _with_triples, text, flags=re.S
    )
    return text


def _with_fix_axis_parameters(match: re.Match[str]) -> str:
    block = match.group(0)
    name = block.split()[2]

    def axis(descr: re.Match[str]) -> str:
        text = descr.group(0)
        if "FIX_AXIS  /* attribute */" not in text or "FIX_AXIS_PAR" in text:
            return text
        points = re.search(r"(\d+)\s+/\* maxAxisPoints \*/", text)
        assert points is not None
        parameters = FIX_AXIS_PARAMETERS.get(name, f"FIX_AXIS_PAR_DIST 0 1 {points.group(1)}")
        return text.replace("      /end AXIS_DESCR", f"        {parameters}\n      /end AXIS_DESCR")

    return re.sub(r"/begin AXIS_DESCR.*?/end AXIS_DESCR", axis, block, flags=re.S)


def _with_pairs(match: re.Match[str]) -> str:
    block = match.group(0)
    count = int(re.search(r"(\d+)\s+/\* numberValuePairs \*/", block).group(1))  # type: ignore[union-attr]
    if "TAB_VERB" in block:
        block = block.replace("/begin COMPU_TAB", "/begin COMPU_VTAB").replace(
            "/end COMPU_TAB", "/end COMPU_VTAB"
        )
        pairs = "".join(f'      {i} "state_{i}"\n' for i in range(count))
    else:
        pairs = "".join(f"      {i} {10 * i}.0\n" for i in range(count))
    return re.sub(r"(numberValuePairs \*/\n)", lambda m: m.group(1) + pairs, block, count=1)


def _with_triples(match: re.Match[str]) -> str:
    block = match.group(0)
    count = int(re.search(r"(\d+)\s+/\* numberValueTriples \*/", block).group(1))  # type: ignore[union-attr]
    triples = "".join(f'      {10 * i} {10 * i + 9} "range_{i}"\n' for i in range(count))
    return re.sub(r"(numberValueTriples \*/\n)", lambda m: m.group(1) + triples, block, count=1)
