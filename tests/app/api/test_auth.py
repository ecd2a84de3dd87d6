"""Bearer tokens (created, listed and revoked with the CLI), required beyond loopback or when
asked; CORS closed by default. SQLite and PostgreSQL."""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError
from starlette.websockets import WebSocketDisconnect

from app.api import create_app
from app.cli import main as cli_main
from app.config import Settings
from tests.support.helpers import service_settings


@pytest.fixture(scope="module")
def secured(backend: str, fresh_url) -> Iterator[tuple[TestClient, str]]:  # type: ignore[no-untyped-def]
    url = fresh_url(backend)
    settings = service_settings(url, require_auth=True)
    with TestClient(create_app(settings, execute_runs=False)) as client:
        yield client, url


def _cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli_main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_tokens_gate_every_api_route(
    secured: tuple[TestClient, str], capsys: pytest.CaptureFixture[str]
) -> None:
    client, url = secured
    response = client.get("/api/datasets")
    assert response.status_code == 401
    assert response.json()["error"]["code"] == "unauthorized"
    assert response.headers["www-authenticate"] == "Bearer"
    assert client.get("/api/health").status_code == 200  # liveness stays open

    code, out, _ = _cli(["token", "create", "--name", "ci", "--database-url", url], capsys)
    assert code == 0
    secret = out.strip()
    assert secret.startswith("mw_")
    auth = {"Authorization": f"Bearer {secret}"}
    assert client.get("/api/datasets", headers=auth).status_code == 200
    bad = {"Authorization": f"Bearer {secret}x"}
    assert client.get("/api/datasets", headers=bad).status_code == 401

    code, out, _ = _cli(["token", "list", "--database-url", url], capsys)
    assert code == 0
    assert "ci" in out
    assert secret not in out  # never shown again
    token_id = out.split()[0]
    code, _, _ = _cli(["token", "revoke", token_id, "--database-url", url], capsys)
    assert code == 0
    assert client.get("/api/datasets", headers=auth).status_code == 401


def test_websocket_needs_the_token_too(secured: tuple[TestClient, str]) -> None:
    client, _ = secured
    with (
        pytest.raises(WebSocketDisconnect) as closed,
        client.websocket_connect("/api/runs/1/stream") as ws,
    ):
        ws.receive_json()
    assert closed.value.code == 1008


def test_auth_is_required_beyond_loopback() -> None:
    assert not Settings(host="127.0.0.1").auth_required
    assert not Settings(host="localhost").auth_required
    assert Settings(host="0.0.0.0").auth_required
    assert Settings(host="192.168.1.20").auth_required
    assert Settings(host="127.0.0.1", require_auth=True).auth_required
    with pytest.raises(ValidationError, match="beyond loopback"):
        Settings(host="0.0.0.0", require_auth=False)


def test_cors_is_closed_by_default(client: TestClient) -> None:
    headers = {"Origin": "https://evil.example", "Access-Control-Request-Method": "GET"}
    response = client.options("/api/datasets", headers=headers)
    assert "access-control-allow-origin" not in response.headers
    response = client.get("/api/health", headers={"Origin": "https://evil.example"})
    assert "access-control-allow-origin" not in response.headers


def test_cors_origins_can_be_opened(database_url: str) -> None:
    settings = service_settings(database_url, cors_origins=["https://dash.example"])
    with TestClient(create_app(settings, execute_runs=False)) as client:
        headers = {"Origin": "https://dash.example", "Access-Control-Request-Method": "GET"}
        response = client.options("/api/datasets", headers=headers)
        assert response.headers["access-control-allow-origin"] == "https://dash.example"


def _concrete(path: str) -> str:
    return re.sub(r"\{[^}]+\}", "1", path)


def test_every_openapi_route_refuses_no_token_and_a_bad_token(
    secured: tuple[TestClient, str],
) -> None:
    client, _ = secured
    spec = client.app.openapi()  # type: ignore[attr-defined]
    checked = 0
    for path, operations in spec["paths"].items():
        for method in operations:
            for headers in ({}, {"Authorization": "Bearer mw_not-a-token"}):
                response = client.request(method, _concrete(path), headers=headers)
                if path == "/api/health":
                    assert response.status_code == 200
                    continue
                assert response.status_code == 401, (method, path, response.text)
                assert response.json()["error"]["code"] == "unauthorized"
                checked += 1
    assert checked >= 2 * 25
    for page in ("/openapi.json", "/docs", "/redoc"):  # the API's rule, not open
        for headers in ({}, {"Authorization": "Bearer mw_not-a-token"}):
            response = client.get(page, headers=headers)
            assert response.status_code == 401, (page, headers)


def test_websocket_refuses_no_token_a_bad_token_and_a_foreign_origin(
    secured: tuple[TestClient, str], capsys: pytest.CaptureFixture[str]
) -> None:
    client, url = secured
    _, out, _ = _cli(["token", "create", "--name", "ws", "--database-url", url], capsys)
    secret = out.strip()
    cases = [
        ("/api/runs/1/stream", {}),
        ("/api/runs/1/stream?token=mw_bad", {}),
        (f"/api/runs/1/stream?token={secret}", {"Origin": "https://evil.example"}),
    ]
    for path, headers in cases:
        with (
            pytest.raises(WebSocketDisconnect) as closed,
            client.websocket_connect(path, headers=headers) as ws,
        ):
            ws.receive_json()
        assert closed.value.code == 1008, (path, headers)
    # the dashboard's own origin and a good token are let in (run 1 does not exist: 4404)
    own = {"Origin": "http://testserver"}
    with client.websocket_connect(f"/api/runs/1/stream?token={secret}", headers=own) as ws:
        first = ws.receive_json()
        with pytest.raises(WebSocketDisconnect) as closed:
            ws.receive_json()
    assert first["type"] == "error"
    assert closed.value.code == 4404


def test_responses_carry_nosniff_and_safe_download_names(client: TestClient) -> None:
    from app.api.routers.runs import content_disposition

    for path in ("/api/health", "/api/datasets", "/datasets", "/api/nope"):
        response = client.get(path)
        assert response.headers["x-content-type-options"] == "nosniff", path
        assert response.headers["x-frame-options"] == "DENY"
    assert content_disposition('x"; filename=../../etc/passwd\r\nSet-Cookie: a=b') == (
        'attachment; filename="x_filename_.._.._etc_passwd_Set-Cookie_a_b"'
    )
    assert content_disposition("...") == 'attachment; filename="download"'


def _token(url: str, capsys: pytest.CaptureFixture[str], *scopes: str) -> dict[str, str]:
    args = ["token", "create", "--name", "-".join(scopes) or "default", "--database-url", url]
    for scope in scopes:
        args += ["--scope", scope]
    code, out, err = _cli(args, capsys)
    assert code == 0, err
    return {"Authorization": f"Bearer {out.strip()}"}


def test_every_writing_route_has_a_declared_scope(secured: tuple[TestClient, str]) -> None:
    """A new POST/PATCH/DELETE route must be put in ROUTE_SCOPES on purpose (else: admin)."""
    from app.api.deps import ROUTE_SCOPES

    client, _ = secured
    writes = {
        f"{method.upper()} {path.removeprefix('/api')}"
        for path, operations in client.app.openapi()["paths"].items()  # type: ignore[attr-defined]
        for method in operations
        if method.upper() not in ("GET", "HEAD", "OPTIONS")
    }
    assert writes == set(ROUTE_SCOPES)
    assert ROUTE_SCOPES["DELETE /datasets/{dataset_id}"] == "admin"
    assert ROUTE_SCOPES["POST /base-maps"] == "admin"


def test_scopes_gate_each_route_and_name_the_missing_scope(
    secured: tuple[TestClient, str], capsys: pytest.CaptureFixture[str]
) -> None:
    """read / run / admin tokens against every API operation: a missing scope is a 403
    ``insufficient_scope`` naming it; a token with the scope gets past the gate."""
    from app.api.deps import route_scope

    client, url = secured
    tokens = {
        ("read",): _token(url, capsys, "read"),
        ("read", "run"): _token(url, capsys),  # the default
        ("read", "run", "admin"): _token(url, capsys, "read", "run", "admin"),
        ("admin",): _token(url, capsys, "admin"),
    }
    checked = 0
    for path, operations in client.app.openapi()["paths"].items():  # type: ignore[attr-defined]
        if path == "/api/health":
            continue
        for method in operations:
            needed = route_scope(method, path)
            for scopes, auth in tokens.items():
                response = client.request(method, _concrete(path), headers=auth)
                if needed in scopes:
                    assert response.status_code not in (401, 403), (method, path, scopes)
                else:
                    assert response.status_code == 403, (method, path, scopes, response.text)
                    error = response.json()["error"]
                    assert error["code"] == "insufficient_scope"
                    assert repr(needed) in error["message"]
                    assert f'scope="{needed}"' in response.headers["www-authenticate"]
                checked += 1
    assert checked >= 4 * 25
    # the docs pages follow the API: read is enough, no token is not
    assert client.get("/openapi.json", headers=tokens[("read",)]).status_code == 200
    assert client.get("/docs", headers=tokens[("read",)]).status_code == 200
    assert client.get("/docs", headers=tokens[("admin",)]).status_code == 403


def test_me_reports_the_callers_scopes(
    secured: tuple[TestClient, str], client: TestClient, capsys: pytest.CaptureFixture[str]
) -> None:
    secured_client, url = secured
    auth = _token(url, capsys, "read")
    me = secured_client.get("/api/me", headers=auth).json()
    assert me["scopes"] == ["read"]
    assert me["auth_required"] is True
    assert isinstance(me["token_id"], int)
    assert secured_client.get("/api/me").status_code == 401
    # auth off (loopback, no tokens): everything, as before scopes existed
    assert client.get("/api/me").json() == {
        "auth_required": False,
        "token_id": None,
        "scopes": ["read", "run", "admin"],
    }


def test_token_create_defaults_to_read_and_run_and_refuses_unknown_scopes(
    secured: tuple[TestClient, str], capsys: pytest.CaptureFixture[str]
) -> None:
    _, url = secured
    code, _, err = _cli(["token", "create", "--name", "dflt", "--database-url", url], capsys)
    assert code == 0
    assert "scopes read,run" in err
    code, _, err = _cli(
        ["token", "create", "--name", "a", "--scope", "admin", "--database-url", url], capsys
    )
    assert code == 0
    assert "scopes admin" in err
    code, _, err = _cli(
        ["token", "create", "--name", "x", "--scope", "root", "--database-url", url], capsys
    )
    assert code == 2
    assert "invalid choice: 'root'" in err
    code, out, _ = _cli(["token", "list", "--database-url", url], capsys)
    assert re.search(r"active\s+read,run\s+last used never\s+dflt", out), out


def test_a_websocket_needs_the_read_scope(
    secured: tuple[TestClient, str], capsys: pytest.CaptureFixture[str]
) -> None:
    client, url = secured
    secret = _token(url, capsys, "run")["Authorization"].removeprefix("Bearer ")
    with (
        pytest.raises(WebSocketDisconnect) as closed,
        client.websocket_connect(f"/api/runs/1/stream?token={secret}") as ws,
    ):
        ws.receive_json()
    assert closed.value.code == 1008
    assert "'read'" in (closed.value.reason or "")
