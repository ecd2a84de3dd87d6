"""The one naming rule (app.io.names), shared by dataset names and channel names: kept as
given but for surrounding whitespace; control, format and surrogate characters refused."""

from __future__ import annotations

import io

import numpy as np
import pytest

from app.io.errors import InputError
from app.io.ingest import ingest
from app.io.names import check_name, without_refused

KEPT = [
    "a/b",
    "..\\..\\etc\\passwd",  # never used as a path, so nothing to fear
    "C:\\logs\\run 1.csv",
    "Drehzahl [1/min]",
    "été 🚗",
    "שם",  # right-to-left text itself is text; only the override characters are refused
    "a\u00a0b",  # a no-break space is a visible space
]
REFUSED = [
    ("a\u202eb", "U+202E (RIGHT-TO-LEFT OVERRIDE) at position 1"),
    ("a\u2066b", "U+2066 (LEFT-TO-RIGHT ISOLATE)"),
    ("\u200bx", "U+200B (ZERO WIDTH SPACE) at position 0"),
    ("x\u200f", "U+200F (RIGHT-TO-LEFT MARK)"),
    ("x\u2060y", "U+2060 (WORD JOINER)"),
    ("x\ufeffy", "U+FEFF (ZERO WIDTH NO-BREAK SPACE)"),
    ("a\tb", "U+0009 at position 1"),
    ("a\nb", "U+000A"),
    ("a\x00b", "U+0000"),
    ("a\x7fb", "U+007F"),
    ("a\x9bb", "U+009B"),  # C1: CSI
    ("a\ud800b", "U+D800"),  # a lone surrogate (JSON "\ud800") cannot be stored
]


@pytest.mark.parametrize("name", KEPT)
def test_names_are_kept_as_given(name: str) -> None:
    assert check_name(f"  {name} ", field="name") == name


@pytest.mark.parametrize(("name", "fragment"), REFUSED)
def test_control_and_format_characters_are_refused_naming_the_code_point(
    name: str, fragment: str
) -> None:
    with pytest.raises(InputError) as info:
        check_name(name, field="name")
    assert (info.value.field, info.value.status) == ("name", 422)
    assert fragment in info.value.message


def test_without_refused_drops_only_refused_characters() -> None:
    assert without_refused("a\u202eb/c\u200b d\x00") == "ab/c d"


def _mcap(channel_name: str) -> bytes:
    import json

    from mcap.writer import Writer

    schema = {"type": "object", "properties": {"time_s": {"type": "number"}}}
    schema["properties"][channel_name] = {"type": "number"}
    buffer = io.BytesIO()
    writer = Writer(buffer)
    writer.start()
    schema_id = writer.register_schema("s", "jsonschema", json.dumps(schema).encode())
    channel = writer.register_channel("/t", "json", schema_id)
    for k in range(3):
        data = json.dumps({channel_name: 1.0 + k, "time_s": k * 0.1}).encode()
        writer.add_message(channel, log_time=k * 10**8, data=data, publish_time=k * 10**8)
    writer.finish()
    return buffer.getvalue()


def _mdf(channel_name: str) -> bytes:
    from asammdf import MDF, Signal

    t = np.arange(5) * 0.1
    mdf = MDF(version="4.10")
    mdf.append([Signal(t * 2, t, name=channel_name)])
    buffer = io.BytesIO()
    mdf.save(buffer)
    mdf.close()
    return buffer.getvalue()


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.parametrize("make", [_mcap, _mdf], ids=["mcap", "mdf4"])
def test_every_format_applies_the_rule_to_channel_names(make) -> None:  # type: ignore[no-untyped-def]
    kept = ingest(make("p/q \u00e9"))
    assert any(name.endswith("p/q \u00e9") for name in kept.signals.names)
    with pytest.raises(InputError) as info:
        ingest(make("p\u202eq"))
    assert info.value.status == 422
    assert "U+202E (RIGHT-TO-LEFT OVERRIDE)" in info.value.message
    assert "channel name" in info.value.message
