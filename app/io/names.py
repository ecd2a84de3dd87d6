"""The one rule for names a user gives: dataset names and channel (column) names.

A name is kept as given — it is never used as a path, so ``/`` and ``\\`` stay — except for
its surrounding whitespace. Only characters that are not visible text are refused: Unicode
categories Cc (C0/C1 controls, tab, newline), Cf (format characters: the bidi overrides
such as U+202E that make a name display as something else, the zero-width spaces U+200B–
U+200F, U+2060, U+FEFF) and Cs (lone surrogates, which no encoding can store).
"""

from __future__ import annotations

import sys
import unicodedata
from functools import cache
from typing import Any

from app.io.errors import InputError

REFUSED_CATEGORIES = frozenset({"Cc", "Cf", "Cs"})


def bad_character(text: str) -> tuple[int, str] | None:
    """Index and character of the first refused character of ``text``, or ``None``."""
    for k, ch in enumerate(text):
        if unicodedata.category(ch) in REFUSED_CATEGORIES:
            return k, ch
    return None


def describe(ch: str) -> str:
    """``U+202E (RIGHT-TO-LEFT OVERRIDE)``; controls have no Unicode name."""
    name = unicodedata.name(ch, "")
    return f"U+{ord(ch):04X}" + (f" ({name})" if name else "")


def check_name(text: str, *, field: str, what: str = "name", line: int | None = None) -> str:
    """``text`` without surrounding whitespace; :class:`InputError` (422, ``field``) naming
    the position and code point of a control or format character."""
    name = text.strip()
    found = bad_character(name)
    if found is not None:
        k, ch = found
        where = f"line {line}: " if line is not None else ""
        raise InputError(
            f"{where}{what} {name!r} contains {describe(ch)} at position {k}; names may not "
            "contain control or invisible formatting characters",
            field=field,
            line=line,
        )
    return name


def without_refused(text: str) -> str:
    """``text`` with every refused character dropped: for names derived from something the
    user did not type as a name (a client's file name)."""
    return "".join(ch for ch in text if unicodedata.category(ch) not in REFUSED_CATEGORIES)


@cache
def name_pattern() -> str:
    """The rule as a JSON-schema ``pattern`` (for OpenAPI): a string of no refused character.
    Astral code points are written ``\\UXXXXXXXX``, which Python's and Rust's regex engines
    read (ECMA-262 without the ``u`` flag has no escape for them); surrogates are left out,
    as no valid JSON string holds one and Rust's engine refuses them in a class."""
    refused, category = REFUSED_CATEGORIES - {"Cs"}, unicodedata.category
    ranges: list[tuple[int, int]] = []
    for code in [c for c in range(sys.maxunicode + 1) if category(chr(c)) in refused]:
        if ranges and ranges[-1][1] == code - 1:
            ranges[-1] = (ranges[-1][0], code)
        else:
            ranges.append((code, code))

    def escape(code: int) -> str:
        return f"\\u{code:04X}" if code <= 0xFFFF else f"\\U{code:08X}"

    parts = [escape(a) if a == b else f"{escape(a)}-{escape(b)}" for a, b in ranges]
    return f"^[^{''.join(parts)}]*$"


def name_schema(schema: dict[str, Any]) -> None:
    """``json_schema_extra`` of a name field: documents :func:`name_pattern` (the service's
    own check gives the clearer error)."""
    schema["pattern"] = name_pattern()
