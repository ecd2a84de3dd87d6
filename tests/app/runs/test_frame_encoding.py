"""The binary encoding of live frames (``?encoding=binary``, app/runs/frame_encoding.py):
decoded, a frame equals its JSON frame to float32 precision (float64 for times), NaN where
JSON has ``null``, and the layout is the documented one (docs/rest-api.md#live-stream)."""

from __future__ import annotations

import json
import struct
from typing import Any

import numpy as np
import pytest

from app.runs.frame_encoding import decode_binary, encode, encode_binary, encode_json


def same_frame(decoded: Any, expected: Any, path: str = "") -> None:
    """``decoded`` (from binary) equals ``expected`` (from JSON): arrays to their dtype's
    precision, NaN for ``null``; everything else exactly."""
    if isinstance(decoded, np.ndarray):
        want = np.array(expected, dtype=np.float64)  # None → NaN
        assert decoded.shape == want.shape, path
        assert np.array_equal(decoded, want.astype(decoded.dtype), equal_nan=True), path
    elif isinstance(decoded, dict):
        assert isinstance(expected, dict), path
        assert decoded.keys() == expected.keys(), path
        for key in decoded:
            same_frame(decoded[key], expected[key], f"{path}.{key}")
    elif isinstance(decoded, list):
        assert isinstance(expected, list), path
        assert len(decoded) == len(expected), path
        for k, (d, e) in enumerate(zip(decoded, expected, strict=True)):
            same_frame(d, e, f"{path}[{k}]")
    else:
        assert decoded == expected, path


FRAME = {
    "type": "delta",
    "sample": 120,
    "progress": 0.4,
    "time_s": 1.7e9 + 0.01,
    "emitted_at": 1.7e9,
    "values": [[1.5, None, 3.25], [0.1, 2e30, -7.0]],
    "variances": [[1.0, 2.0, 3.0], [4.0, None, 6.0]],
    "visits": [[0, 3, 1], [2, 0, 5]],
    "active_cell": [1, 2],
    "trajectory": {"time": [1.7e9 + 0.01, 1.7e9 + 0.02], "points": [[800.0, 12.5], [810.0, None]]},
    "series": {
        "u1": {"time": [0.0, 0.02, 0.04], "values": [1.0, None, 3.0]},
        "empty": {"time": [], "values": []},
        "arrays": {"time": [0.5], "values": [0.25]},  # a series key is any channel name
    },
    "metrics": {"rmse": 0.5, "nis": None},
    "rejected": {"mask": 3},
}


def test_binary_round_trip_equals_the_json_frame_with_nan_for_null() -> None:
    message = encode(FRAME, "binary")
    assert isinstance(message, bytes)
    decoded = decode_binary(message)
    same_frame(decoded, json.loads(encode_json(FRAME)))
    assert decoded["values"].dtype == np.float32
    assert np.isnan(decoded["values"][0, 1])
    assert np.isnan(decoded["series"]["u1"]["values"][1])
    assert np.isnan(decoded["trajectory"]["points"][1, 1])
    # Times are float64: an absolute time keeps its 10 ms (float32 would round to 128 s).
    assert decoded["trajectory"]["time"].dtype == np.float64
    assert decoded["trajectory"]["time"][1] - decoded["trajectory"]["time"][0] == pytest.approx(
        0.01, abs=1e-6
    )
    assert decoded["time_s"] == FRAME["time_s"]  # scalars stay in the JSON part, as they are
    assert decoded["series"]["empty"] == {"time": [], "values": []}
    assert FRAME["values"][0][1] is None  # the caller's frame is not changed


def test_the_layout_is_the_documented_one() -> None:
    message = encode_binary(FRAME)
    magic, version, length = struct.unpack_from("<4sB3xI", message)
    assert (magic, version) == (b"MWLF", 1)
    head = json.loads(message[12 : 12 + length])  # strict JSON: no NaN in it
    assert head["frame"]["values"] is None
    assert head["frame"]["metrics"] == {"rmse": 0.5, "nis": None}
    start = 12 + length + (-(12 + length) % 8)
    refs = {tuple(ref["path"]): ref for ref in head["arrays"]}
    values = refs[("values",)]
    assert values["dtype"] == "f32"
    assert values["shape"] == [2, 3]
    assert values["offset"] % 8 == 0
    block = np.frombuffer(message, "<f4", count=6, offset=start + values["offset"])
    assert block[0] == 1.5
    assert refs[("series", "u1", "time")]["dtype"] == "f64"
    assert ("series", "empty", "values") not in refs  # an empty array stays in the JSON
    assert all(ref["offset"] % 8 == 0 for ref in head["arrays"])


def test_frames_without_arrays_and_bad_messages() -> None:
    status = {"type": "status", "status": "running", "error": None, "progress": 0.5}
    assert decode_binary(encode_binary(status)) == status
    assert (
        encode(status, "json") == '{"type":"status","status":"running","error":null,"progress":0.5}'
    )
    with pytest.raises(ValueError, match="MWLF"):
        decode_binary(b"{" + encode_binary(status)[1:])
    with pytest.raises(ValueError, match="header"):
        decode_binary(b"MWLF")
