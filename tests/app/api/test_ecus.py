"""ECUs over HTTP (the real app, SQLite and PostgreSQL): an A2L with a HEX image written by
bincopy, its maps listed and decoded, New-run prefill with channel matching, a base map, a
run linked to the A2L map and its DCM / CDFX / patched-image exports; bad files are refused
naming the field and store nothing (docs/calibration.md#rest-and-cli)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import bincopy
import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.api import create_app
from app.calibration.cdfx import read_cdfx
from app.calibration.values import read_dcm_values
from app.services.a2l_cache import CacheLimits, prune
from tests.app.api.test_uploads import _count
from tests.app.calibration.demo_a2l import full_demo_text
from tests.frontend import ecu_files as ef
from tests.support.helpers import service_settings, upload_ok, wait_run

pytestmark = pytest.mark.slow  # the A2L is parsed by pya2ldb in a child process (seconds)

MAP = ef.MAP_NAME
VALUES = np.array(ef.VALUES, dtype=float)
MAP_BYTES = len(ef.map_record())


@pytest.fixture(scope="module")
def a2l_bytes() -> bytes:
    return full_demo_text().encode("latin-1")


@pytest.fixture(scope="module")
def hex_image() -> bytes:
    image = bincopy.BinFile()
    image.add_binary(ef.map_record(), address=ef.MAP_ADDRESS)
    image.add_binary(bytes(range(64)), address=ef.MAP_ADDRESS + 0x200)  # other memory
    return image.as_ihex().encode()


@pytest.fixture(scope="module")
def client(database_url: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    cache = tmp_path_factory.mktemp("ecu-cache")
    with TestClient(create_app(service_settings(database_url, cache_dir=cache))) as c:
        yield c


@pytest.fixture(scope="module")
def ecu(client: TestClient, a2l_bytes: bytes, hex_image: bytes) -> dict:
    response = client.post(
        "/api/ecus",
        files={"a2l": ("demo.a2l", a2l_bytes), "values": ("ecu.hex", hex_image)},
    )
    assert response.status_code == 201, response.text
    return response.json()


@pytest.fixture(scope="module")
def drive(client: TestClient) -> dict:
    return upload_ok(client, ef.drive_log(duration_s=30.0), "drive.csv")


def test_upload_lists_searches_and_decodes(client: TestClient, ecu: dict) -> None:
    assert ecu["name"] == "demo"
    assert ecu["values_format"] == "hex"
    assert ecu["characteristics"] > 20
    assert len(ecu["a2l_sha256"]) == 64
    assert ecu["notes"] == []
    listed = client.get("/api/ecus").json()
    assert ecu["id"] in [e["id"] for e in listed["items"]]
    assert client.get(f"/api/ecus/{ecu['id']}").json()["name"] == "demo"

    maps = client.get(f"/api/ecus/{ecu['id']}/maps", params={"type": "MAP,CURVE"}).json()
    names = {m["name"] for m in maps["items"]}
    assert maps["total"] == len(names) >= 12
    assert {m["type"] for m in maps["items"]} == {"MAP", "CURVE"}
    assert {MAP, "ASAM.C.CURVE.FIX_AXIS.PAR_DIST", "ASAM.C.MAP.COM_AXIS.FIX_AXIS"} <= names
    found = client.get(f"/api/ecus/{ecu['id']}/maps", params={"q": "fix_axis_par_list"}).json()
    assert [m["name"] for m in found["items"]] == ["ASAM.C.CURVE.FIX_AXIS.PAR_LIST"]
    page = client.get(f"/api/ecus/{ecu['id']}/maps", params={"limit": 2, "offset": 1}).json()
    assert (len(page["items"]), page["total"]) == (2, ecu["characteristics"])

    doc = client.get(f"/api/ecus/{ecu['id']}/maps/{MAP}").json()
    assert (doc["type"], doc["shape"], doc["unit"]) == ("MAP", [4, 5], ef.MAP_UNIT)
    assert [a["input_quantity"] for a in doc["axes"]] == [ef.X_QUANTITY, ef.Y_QUANTITY]
    assert doc["values"]["axes"] == [list(map(float, ef.X_POINTS)), list(map(float, ef.Y_POINTS))]
    assert np.array_equal(doc["values"]["values"], VALUES)
    assert doc["values"]["unit"] == ef.MAP_UNIT


def test_bad_query_and_unknown_names(client: TestClient, ecu: dict) -> None:
    response = client.get(f"/api/ecus/{ecu['id']}/maps", params={"type": "MAP,CUBE"})
    assert (response.status_code, response.json()["error"]["field"]) == (422, "type")
    response = client.get(f"/api/ecus/{ecu['id']}/maps/NOPE.MAP")
    assert response.status_code == 422
    assert "NOPE.MAP" in response.json()["error"]["message"]
    assert client.get("/api/ecus/999999/maps").status_code == 404


def test_a_map_the_image_does_not_cover_is_a_4xx_naming_it(client: TestClient, ecu: dict) -> None:
    name = "ASAM.C.CURVE.STD_AXIS"
    response = client.get(f"/api/ecus/{ecu['id']}/maps/{name}")
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert name in error["message"]
    assert error["field"] == "values"


@pytest.mark.parametrize(
    ("files", "status", "field"),
    [
        ({"a2l": ("x.a2l", b"this is not an A2L\n")}, 422, "a2l"),
        ({"a2l": ("x.a2l", bytes(range(256)) * 4)}, 422, "a2l"),
        ({"a2l": ("x.a2l", b"")}, 422, "a2l"),
        ({"values": ("x.hex", b":00000001FF\n")}, 422, "a2l"),
        ("A2L", 415, "values"),  # garbage values beside a good A2L
        ("A2L+bad checksum", 422, "values"),
    ],
)
def test_bad_uploads_are_refused_and_nothing_is_stored(
    client: TestClient,
    database_url: str,
    a2l_bytes: bytes,
    ecu: dict,
    files: object,
    status: int,
    field: str,
) -> None:
    if files == "A2L":
        files = {"a2l": ("x.a2l", a2l_bytes), "values": ("x.bin", b"\x00\x01garbage" * 50)}
    elif files == "A2L+bad checksum":
        corrupt = b":0400000001020304F1\n:00000001FF\n"  # the checksum should be F2
        files = {"a2l": ("x.a2l", a2l_bytes), "values": ("x.hex", corrupt)}
    before = _count(database_url)
    response = client.post("/api/ecus", files=files)  # type: ignore[arg-type]
    assert response.status_code == status, response.text
    assert response.json()["error"]["field"] == field
    assert _count(database_url) == before


def test_dcm_values_unknown_names_are_notes_and_bad_axes_a_4xx(
    client: TestClient, ecu: dict, a2l_bytes: bytes, hex_image: bytes
) -> None:
    from app.io.dcm import DcmBlock, blocks_to_dcm

    fixed = "ASAM.C.CURVE.FIX_AXIS.PAR_DIST"  # FIX_AXIS_PAR_DIST 0 20 6: 0, 20, …, 100
    axes = [(ef.X_QUANTITY, "", [-10.0, 0.0, 10.0, 20.0]), (ef.Y_QUANTITY, "", [0, 1, 2, 3, 4])]
    dcm = blocks_to_dcm(
        [
            DcmBlock(MAP, axes, VALUES, ef.MAP_UNIT),
            DcmBlock(fixed, [("x", "", [0, 10, 20, 30, 40, 50])], np.arange(6.0)),
            DcmBlock("NOT.IN.THE.A2L", axes, VALUES),
        ]
    ).encode()
    uploaded = client.post(
        "/api/ecus", files={"a2l": ("d.a2l", a2l_bytes), "values": ("d.dcm", dcm)}
    )
    assert uploaded.status_code == 201, uploaded.text
    body = uploaded.json()
    assert body["values_format"] == "dcm"
    assert any("NOT.IN.THE.A2L" in note for note in body["notes"])
    assert not any(MAP in note or fixed in note for note in body["notes"])
    doc = client.get(f"/api/ecus/{body['id']}/maps/{MAP}").json()
    assert np.array_equal(doc["values"]["values"], VALUES)
    response = client.get(f"/api/ecus/{body['id']}/maps/{fixed}")
    assert response.status_code == 422
    assert fixed in response.json()["error"]["message"]
    replaced = client.put(f"/api/ecus/{body['id']}/values", files={"values": ("e.hex", hex_image)})
    assert (replaced.status_code, replaced.json()["values_format"]) == (200, "hex")
    doc = client.get(f"/api/ecus/{body['id']}/maps/{MAP}").json()
    assert np.array_equal(doc["values"]["values"], VALUES)
    assert client.get(f"/api/ecus/{body['id']}/maps/{fixed}").status_code == 422  # not in it
    assert client.delete(f"/api/ecus/{body['id']}").status_code == 204
    assert client.get(f"/api/ecus/{body['id']}").status_code == 404


def test_an_upload_over_the_size_limit_is_413_naming_the_file(
    database_url: str, a2l_bytes: bytes, tmp_path: Path
) -> None:
    settings = service_settings(database_url, cache_dir=tmp_path, max_upload_mb=0.05)
    assert len(a2l_bytes) > 0.05 * 2**20
    with TestClient(create_app(settings, execute_runs=False)) as small:
        before = _count(database_url)
        response = small.post("/api/ecus", files={"a2l": ("big.a2l", a2l_bytes)})
        assert response.status_code == 413, response.text
        assert response.json()["error"]["field"] == "a2l"
        assert _count(database_url) == before


def test_template_matches_channels_ignoring_tool_suffixes(
    client: TestClient, ecu: dict, drive: dict
) -> None:
    response = client.get(
        f"/api/ecus/{ecu['id']}/maps/{MAP}/template", params={"dataset_id": drive["id"]}
    )
    assert response.status_code == 200, response.text
    doc = response.json()
    assert doc["channels"] == {
        "matched": {ef.X_QUANTITY: ef.X_CHANNEL, ef.Y_QUANTITY: ef.Y_QUANTITY},
        "unmatched": [],
    }
    assert [a["name"] for a in doc["table"]["axes"]] == [ef.X_CHANNEL, ef.Y_QUANTITY]
    assert doc["table"]["axes"][0]["breakpoints"] == list(map(float, ef.X_POINTS))
    assert doc["table"]["output_unit"] == ef.MAP_UNIT
    assert doc["output"] is None  # the A2L does not name the measured output
    assert np.array_equal(doc["base_map"]["values"], VALUES)
    assert doc["calibration"] == {"ecu_id": ecu["id"], "map": MAP}

    other = upload_ok(client, "time,a,b\n0,1,2\n1,2,3\n", "other.csv")
    doc = client.get(
        f"/api/ecus/{ecu['id']}/maps/{MAP}/template", params={"dataset_id": other["id"]}
    ).json()
    assert doc["channels"]["unmatched"] == [ef.X_QUANTITY, ef.Y_QUANTITY]
    assert [a["name"] for a in doc["table"]["axes"]] == [ef.X_QUANTITY, ef.Y_QUANTITY]
    value = "ASAM.C.SCALAR.FLOAT32_IEEE.IDENTICAL"
    response = client.get(f"/api/ecus/{ecu['id']}/maps/{value}/template")
    assert response.status_code == 422
    assert "only a MAP or CURVE" in response.json()["error"]["message"]


def test_linked_run_exports_dcm_cdfx_and_a_patched_image(
    client: TestClient, a2l_bytes: bytes, drive: dict, hex_image: bytes
) -> None:
    files = {"a2l": ("mine.a2l", a2l_bytes), "values": ("ecu.hex", hex_image)}
    ecu = client.post("/api/ecus", files=files).json()  # its own: deleted at the end
    template = client.get(
        f"/api/ecus/{ecu['id']}/maps/{MAP}/template", params={"dataset_id": drive["id"]}
    ).json()
    base = client.post(f"/api/ecus/{ecu['id']}/maps/{MAP}/base-map")
    assert base.status_code == 201, base.text
    assert base.json()["name"] == f"mine:{MAP}"
    assert np.array_equal(base.json()["values"], VALUES)
    table = {
        "axes": [
            {"name": a["name"], "breakpoints": a["breakpoints"]} for a in template["table"]["axes"]
        ]
    }
    body = {
        "dataset_id": drive["id"],
        "estimator": "skf",
        "signals": {"y": ef.OUTPUT},
        "table": table,
        "base_map_id": base.json()["id"],
        "calibration": template["calibration"],
        "config": {"sigma_v": 0.5, "sigma_w": 0.05, "p0": 100.0},
    }
    # a link that does not fit is refused before anything is stored
    wrong = {**body, "calibration": {"ecu_id": ecu["id"], "map": "ASAM.C.CURVE.STD_AXIS"}}
    response = client.post("/api/runs", json=wrong)
    assert (response.status_code, response.json()["error"]["field"]) == (422, "calibration.map")
    response = client.post(
        "/api/runs", json={**body, "calibration": {"ecu_id": 999999, "map": MAP}}
    )
    assert (response.status_code, response.json()["error"]["field"]) == (404, "calibration.ecu_id")

    created = client.post("/api/runs", json=body)
    assert created.status_code == 201, created.text
    assert created.json()["table"]["calibration"] == {"ecu_id": ecu["id"], "map": MAP}
    run = wait_run(client, created.json()["id"])
    assert run["status"] == "succeeded", run["error"]

    def export(fmt: str) -> bytes:
        response = client.get(f"/api/runs/{run['id']}/export", params={"format": fmt})
        assert response.status_code == 200, response.text
        return response.content

    import json

    document = json.loads(export("json"))
    learned = np.array(document["values"])
    stored = np.array(document["calibration"]["values"])
    error = np.array(document["quantization_error"])
    assert stored.shape == error.shape == VALUES.shape
    assert np.array_equal(stored, np.round(learned))  # SWORD, IDENTICAL: whole hours
    assert np.allclose(error, stored - learned)
    assert np.all(np.abs(error) <= 0.5)
    assert not np.allclose(stored, VALUES)  # the log moved the map (+15 h)

    dcm = read_dcm_values(export("dcm"))
    assert list(dcm) == [MAP]
    assert np.array_equal(dcm[MAP].values, stored)
    cdfx = read_cdfx(export("cdfx"))
    assert list(cdfx) == [MAP]
    assert np.array_equal(cdfx[MAP].values, stored)
    assert np.array_equal(cdfx[MAP].axes[0], ef.X_POINTS)

    patched = export("image")
    before, after = ef.memory(hex_image), ef.memory(patched)
    assert before.keys() == after.keys()
    changed = [a for a in before if before[a] != after[a]]
    assert changed
    assert all(ef.MAP_ADDRESS <= a < ef.MAP_ADDRESS + MAP_BYTES for a in changed)
    # the patched image decodes to the stored values (a new ECU with it)
    again = client.post(
        "/api/ecus",
        files={
            "a2l": ("demo.a2l", full_demo_text().encode("latin-1")),
            "values": ("p.hex", patched),
        },
    ).json()
    decoded = client.get(f"/api/ecus/{again['id']}/maps/{MAP}").json()["values"]
    assert np.array_equal(decoded["values"], stored)

    # the ECU goes: the run keeps its map and JSON; CDFX and the image need the ECU
    assert client.delete(f"/api/ecus/{ecu['id']}").status_code == 204
    response = client.get(f"/api/runs/{run['id']}/export", params={"format": "cdfx"})
    assert (response.status_code, response.json()["error"]["field"]) == (409, "format")
    assert "quantization_error" not in json.loads(export("json"))
    assert read_dcm_values(export("dcm"))  # the plain DCM export of an unlinked run


def test_unlinked_runs_have_no_cdfx_or_image(client: TestClient, drive: dict) -> None:
    body = {
        "dataset_id": drive["id"],
        "estimator": "skf",
        "signals": {"y": ef.OUTPUT},
        "table": {"axes": [{"name": ef.Y_QUANTITY, "breakpoints": [0, 2, 4]}]},
    }
    run = wait_run(client, client.post("/api/runs", json=body).json()["id"])
    for fmt in ("cdfx", "image"):
        response = client.get(f"/api/runs/{run['id']}/export", params={"format": fmt})
        assert response.status_code == 409
        assert response.json()["error"]["field"] == "format"
    assert client.get(f"/api/runs/{run['id']}/export", params={"format": "dcm"}).status_code == 200


def test_the_a2l_cache_keeps_within_its_bounds(tmp_path: Path) -> None:
    import os

    for i, (letter, size) in enumerate(zip("abcd", (100, 200, 300, 400), strict=True)):
        path = tmp_path / f"{letter * 64}.json"
        path.write_bytes(b"x" * size)
        os.utime(path, (1000 + i, 1000 + i))
    (tmp_path / ".a2l-parsing").mkdir()  # a parse in progress is never touched
    removed = prune(CacheLimits(tmp_path, max_files=10, max_bytes=750), keep="a" * 64)
    left = sorted(p.name[:1] for p in tmp_path.iterdir())
    # oldest first, but the entry in use stays: b (200 B) goes, then c (300 B)
    assert (removed, left) == (2, [".", "a", "d"])
    removed = prune(CacheLimits(tmp_path, max_files=1, max_bytes=10**6))
    assert (removed, sorted(p.name[:1] for p in tmp_path.iterdir())) == (1, [".", "d"])


def _image_with(values: np.ndarray) -> bytes:
    """The map's record (as :func:`ef.map_record` lays it out) holding ``values``."""
    import struct

    record = bytearray(ef.map_record())
    start = len(record) - 2 * values.size  # the SWORD values close the record
    record[start:] = struct.pack(f"<{values.size}h", *values.astype(int).ravel(order="F"))
    image = bincopy.BinFile()
    image.add_binary(bytes(record), address=ef.MAP_ADDRESS)
    return image.as_ihex().encode()


def test_a_map_beyond_its_limits_is_refused_when_used_and_nothing_is_stored(
    client: TestClient, database_url: str, a2l_bytes: bytes, drive: dict
) -> None:
    """The upload stores the ECU (its other maps stay usable); the map's values, its New-run
    template and a base map of it are each a 422 naming the map, the cell, the value and the
    limit, and no row is written."""
    from app.io.dcm import DcmBlock, blocks_to_dcm

    high = VALUES.copy()
    high[3, 4] = 32500.0  # an SWORD holds it; the demo's UPPER_LIMIT is 32267
    axes = [(ef.X_QUANTITY, "", list(ef.X_POINTS)), (ef.Y_QUANTITY, "", list(ef.Y_POINTS))]
    wide_axis = [(ef.X_QUANTITY, "", [-10.0, 0.0, 10.0, 130.0]), axes[1]]  # axis limit 127
    cases = [
        ("hex", _image_with(high), "HEX", "cell (3, 4) is 32500.0, above the upper limit of"),
        (
            "dcm",
            blocks_to_dcm([DcmBlock(MAP, axes, high, ef.MAP_UNIT)]).encode(),
            "DCM",
            "cell (3, 4) is 32500.0, above the upper limit of [-32268, 32267]",
        ),
        (
            "dcm",
            blocks_to_dcm([DcmBlock(MAP, wide_axis, VALUES, ef.MAP_UNIT)]).encode(),
            "DCM",
            f"axis X ({ef.X_QUANTITY}) point 3 is 130.0, above the upper limit of the axis "
            "[-128, 127]",
        ),
    ]
    for fmt, data, source, message in cases:
        uploaded = client.post(
            "/api/ecus", files={"a2l": ("lim.a2l", a2l_bytes), "values": (f"v.{fmt}", data)}
        )
        assert uploaded.status_code == 201, uploaded.text  # refused when the map is used
        ecu_id = uploaded.json()["id"]
        before = _count(database_url)
        for method, path in [
            ("get", f"/api/ecus/{ecu_id}/maps/{MAP}"),
            ("get", f"/api/ecus/{ecu_id}/maps/{MAP}/template?dataset_id={drive['id']}"),
            ("post", f"/api/ecus/{ecu_id}/maps/{MAP}/base-map"),
        ]:
            response = getattr(client, method)(path)
            assert response.status_code == 422, (path, response.text)
            error = response.json()["error"]
            assert error["field"] == "values"
            assert error["message"].startswith(f"{source} {MAP}: "), error
            assert message in error["message"], error
        assert _count(database_url) == before  # no base map, nothing else
        listed = client.get(f"/api/ecus/{ecu_id}/maps", params={"q": MAP})
        assert listed.status_code == 200  # the ECU itself stays usable
        assert [m["name"] for m in listed.json()["items"]] == [MAP]
        assert client.delete(f"/api/ecus/{ecu_id}").status_code == 204


def test_a_linked_table_that_does_not_fit_the_map_is_refused(
    client: TestClient, database_url: str, ecu: dict, drive: dict
) -> None:
    """``check_table``: more points than the A2L's maxAxisPoints, or FIX_AXIS points other
    than the A2L's, are a 422 naming the axis' breakpoints; no run is stored."""
    curve = "ASAM.C.CURVE.STD_AXIS"  # STD_AXIS, at most 8 points
    fixed = "ASAM.C.MAP.COM_AXIS.FIX_AXIS"  # Y: FIX_AXIS_PAR_DIST 0 1 3 → 0, 1, 2
    base = {
        "dataset_id": drive["id"],
        "estimator": "skf",
        "signals": {"y": ef.OUTPUT},
        "config": {"sigma_v": 0.5, "sigma_w": 0.05, "p0": 100.0},
    }
    cases = [
        (
            curve,
            [{"name": ef.Y_QUANTITY, "breakpoints": [0.5 * k for k in range(9)]}],
            "table.axes[0].breakpoints",
            "holds at most 8 points; the table has 9",
        ),
        (
            fixed,
            [
                {"name": ef.X_CHANNEL, "breakpoints": [-10, -5, 0, 5, 10, 15, 20, 25]},
                {"name": ef.Y_QUANTITY, "breakpoints": [0, 1, 3]},
            ],
            "table.axes[1].breakpoints",
            "is a FIX_AXIS with points [0.0, 1.0, 2.0]",
        ),
    ]
    before = _count(database_url)
    for name, axes, field, message in cases:
        body = {**base, "table": {"axes": axes}, "calibration": {"ecu_id": ecu["id"], "map": name}}
        response = client.post("/api/runs", json=body)
        assert response.status_code == 422, response.text
        error = response.json()["error"]
        assert (error["field"], name in error["message"]) == (field, True), error
        assert message in error["message"], error
    assert _count(database_url) == before


def test_an_a2l_the_parser_refuses_is_a_422_and_nothing_is_stored(
    client: TestClient, database_url: str, a2l_bytes: bytes
) -> None:
    """Cut off inside a CHARACTERISTIC: the sniff sees no '/end MODULE' and calls it
    truncated; with the ends named in a comment it passes the sniff and pya2ldb's parser
    refuses it. Each is a 422 naming ``a2l``, and no row is written."""
    cut = a2l_bytes[: a2l_bytes.index(b"/begin CHARACTERISTIC") + 40]
    before = _count(database_url)
    for data, message in (
        (cut, "ends before '/end MODULE': it is truncated"),
        (cut + b"\n/* /end MODULE /end PROJECT */\n", "does not parse"),
    ):
        response = client.post("/api/ecus", files={"a2l": ("cut.a2l", data)})
        assert response.status_code == 422, response.text
        error = response.json()["error"]
        assert error["field"] == "a2l"
        assert message in error["message"], error
    assert _count(database_url) == before
