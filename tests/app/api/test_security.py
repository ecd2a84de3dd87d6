"""Other sites cannot drive the API, and viewers cannot take the server down:

* the Host allowlist (DNS rebinding): 400 over HTTP, 403 at a WebSocket handshake; the
  WebSocket Origin is compared with the allowlist, never with the request's own Host;
* a Content-Security-Policy on every response, the dashboard's import map allowed by hash;
* viewer limits (per run, per client, in all) with a reason, and a revoked token's sockets
  closed within a second;
* against a real ``mapwise serve``: DNS-rebinding probes all refused, 1000 viewers of one
  run held to the cap with bounded memory and event-loop lag, and an idle keep-alive
  connection still open when a client (httpx keeps one 5 s) reuses it.
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import os
import re
import socket
import threading
import time
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from app.api.routers.stream import allowed_origin
from app.config import Settings
from app.runs.hub import LiveHub, ViewerLimitError
from tests.support.helpers import log_csv, run_body
from tests.support.server import Server

ATTACKER = "attacker.example"


# --- Host allowlist and Origin, in process -------------------------------------------------


def test_allowed_hosts_default_to_loopback_names_plus_the_configured_host() -> None:
    assert Settings().trusted_hosts == ["localhost", "127.0.0.1", "[::1]"]
    assert Settings(host="0.0.0.0").trusted_hosts == ["localhost", "127.0.0.1", "[::1]"]
    assert Settings(host="::").trusted_hosts == ["localhost", "127.0.0.1", "[::1]"]
    assert Settings(host="maps.lab").trusted_hosts[-1] == "maps.lab"
    assert Settings(allowed_hosts="maps.lab, ::1").trusted_hosts == ["maps.lab", "[::1]"]
    assert Settings(allowed_hosts="*.lab.example").trusted_hosts == ["*.lab.example"]
    with pytest.raises(ValueError, match="wildcard"):
        Settings(allowed_hosts="maps.*.example")


def test_a_foreign_host_is_refused_before_any_route(client: TestClient) -> None:
    dataset = client.post("/api/datasets/simulate", json={"scenario": "skf-sim1"}).json()["id"]
    evil = {"Host": f"{ATTACKER}:8327", "Origin": f"http://{ATTACKER}:8327"}
    probes = [
        ("GET", "/api/datasets"),
        ("GET", f"/api/datasets/{dataset}"),
        ("DELETE", f"/api/datasets/{dataset}?force=true"),
        ("GET", "/api/health"),
        ("GET", "/datasets"),
    ]
    for method, path in probes:
        response = client.request(method, path, headers=evil)
        assert response.status_code == 400, (method, path)
        assert "content-security-policy" in response.headers
    assert client.get(f"/api/datasets/{dataset}").status_code == 200  # still there
    with (
        pytest.raises(WebSocketDisconnect) as closed,
        client.websocket_connect(f"/api/runs/{dataset}/stream", headers=evil) as ws,
    ):
        ws.receive_json()
    assert closed.value.code == 1008


def _ws(host: str) -> Any:
    return SimpleNamespace(headers={"host": host})


def test_the_websocket_origin_is_checked_against_the_allowlist_not_the_host() -> None:
    settings = Settings(port=8327)
    own = _ws("127.0.0.1:8327")
    assert allowed_origin("http://127.0.0.1:8327", own, settings)
    assert allowed_origin("http://localhost:8327", own, settings)
    assert allowed_origin("http://[::1]:8327", own, settings)
    # DNS rebinding: Origin and Host both carry the attacker's name, and still no
    rebound = _ws(f"{ATTACKER}:8327")
    assert not allowed_origin(f"http://{ATTACKER}:8327", rebound, settings)
    assert not allowed_origin("null", own, settings)
    assert not allowed_origin("file://", own, settings)
    assert not allowed_origin("http://localhost.attacker.example", own, settings)
    opened = Settings(cors_origins="https://dash.example", allowed_hosts="*.lab.example")
    assert allowed_origin("https://dash.example", own, opened)
    assert allowed_origin("https://maps.lab.example", own, opened)
    assert not allowed_origin("https://lab.example.evil", own, opened)


# --- Content-Security-Policy ----------------------------------------------------------------


def _directives(policy: str) -> dict[str, str]:
    return dict(d.strip().split(" ", 1) for d in policy.split(";"))


def test_every_response_carries_a_content_security_policy(client: TestClient) -> None:
    for path in ("/api/health", "/api/datasets", "/api/nope", "/static/js/main.js"):
        policy = _directives(client.get(path).headers["content-security-policy"])
        assert policy["default-src"] == "'self'", path
        assert policy["script-src"] == "'self'", path
        assert policy["frame-ancestors"] == "'none'"
    page = client.get("/datasets")
    policy = _directives(page.headers["content-security-policy"])
    importmap = re.search(r'<script type="importmap">(.*?)</script>', page.text, re.S)
    assert importmap is not None
    digest = base64.b64encode(hashlib.sha256(importmap[1].encode()).digest()).decode()
    assert policy["script-src"] == f"'self' 'sha256-{digest}'"  # only that inline script
    assert policy["default-src"] == "'self'"


# --- viewer limits, in process --------------------------------------------------------------


def test_the_hub_holds_each_viewer_limit_and_says_which() -> None:
    async def scenario() -> None:
        hub = LiveHub(max_per_run=3, max_per_client=4, max_total=5)
        viewers = [hub.subscribe(1, client="a") for _ in range(3)]
        with pytest.raises(ViewerLimitError, match="run 1 has its maximum of 3 viewers"):
            hub.subscribe(1, client="b")
        viewers.append(hub.subscribe(2, client="a"))
        with pytest.raises(ViewerLimitError, match="this client has its maximum of 4"):
            hub.subscribe(3, client="a")
        viewers.append(hub.subscribe(3, client="b", token_id=7))
        with pytest.raises(ViewerLimitError, match="the server has its maximum of 5"):
            hub.subscribe(4, client="c")
        assert hub.refused == 3
        for viewer in viewers:
            hub.unsubscribe(viewer)
            hub.unsubscribe(viewer)  # twice is harmless
        assert (hub.total, hub.viewers, hub.by_client, hub.by_token) == (0, {}, {}, {})
        assert len([hub.subscribe(1, client="a") for _ in range(3)]) == 3

    asyncio.run(scenario())


def test_closing_a_token_closes_only_its_viewers() -> None:
    async def scenario() -> None:
        hub = LiveHub()
        mine = [hub.subscribe(1, token_id=7), hub.subscribe(2, token_id=7)]
        other = hub.subscribe(1, token_id=8)
        assert sorted(hub.token_ids()) == [7, 8]
        assert hub.close_tokens({7}, "the token was revoked") == 2
        assert all(v.closed.is_set() and v.close_reason == "the token was revoked" for v in mine)
        assert not other.closed.is_set()
        hub.handle({"kind": "status", "run_id": 1, "status": "running", "error": None})
        assert mine[0].queue.empty()  # a closed viewer queues nothing more
        assert not other.queue.empty()

    asyncio.run(scenario())


def test_a_viewer_over_the_limit_gets_1013_with_the_reason(database_url: str) -> None:
    from app.api import create_app
    from tests.support.helpers import service_settings

    settings = service_settings(database_url, max_viewers_per_run=2, run_workers=1)
    with TestClient(create_app(settings)) as client:
        dataset = client.post("/api/datasets/simulate", json={"scenario": "skf-sim1"}).json()
        run = client.post("/api/runs", json=run_body(dataset["id"]))
        assert run.status_code == 201, run.text
        path = f"/api/runs/{run.json()['id']}/stream"
        with client.websocket_connect(path) as a, client.websocket_connect(path) as b:
            assert a.receive_json()["type"] == "full"
            assert b.receive_json()["type"] == "full"
            with (
                pytest.raises(WebSocketDisconnect) as closed,
                client.websocket_connect(path) as c,
            ):
                c.receive_json()
            assert closed.value.code == 1013
            assert "maximum of 2 viewers" in (closed.value.reason or "")
        with client.websocket_connect(path) as again:  # the others left: room again
            assert again.receive_json()["type"] == "full"


# --- against a real server ------------------------------------------------------------------


def _raw_handshake(port: int, path: str, *, host: str, origin: str | None) -> int:
    """The HTTP status a WebSocket handshake gets (101 = accepted), over a bare socket so
    Host and Origin are exactly what an attacker's browser would send."""
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [
        f"GET {path} HTTP/1.1",
        f"Host: {host}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
    ]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        head = b""
        while b"\r\n" not in head:
            chunk = s.recv(1024)
            if not chunk:
                break
            head += chunk
    return int(head.split()[1])


@pytest.fixture(scope="module")
def live(fresh_url) -> Iterator[tuple[Server, int, int]]:  # type: ignore[no-untyped-def]
    """A real server on SQLite with one dataset and one finished run."""
    server = Server(fresh_url("sqlite"))
    try:
        dataset = server.post("/api/datasets", files={"file": ("log.csv", log_csv(600).encode())})
        assert dataset.status_code == 201, dataset.text
        run = server.post("/api/runs", json=run_body(dataset.json()["id"]))
        assert run.status_code == 201, run.text
        server.wait_run(run.json()["id"], ("succeeded",))
        yield server, dataset.json()["id"], run.json()["id"]
    finally:
        server.stop()


@pytest.mark.slow
def test_dns_rebinding_probes_are_all_refused(live: tuple[Server, int, int]) -> None:
    """Host and Origin of a rebound attacker page (its name now resolving to 127.0.0.1):
    every HTTP request 400, every WebSocket handshake 403; nothing deleted."""
    server, dataset, run = live
    port = server.port
    hosts = [f"{ATTACKER}:{port}", ATTACKER, f"127.0.0.1.{ATTACKER}:{port}"]
    http_probes = [
        ("GET", "/api/datasets"),
        ("GET", f"/api/datasets/{dataset}"),
        ("DELETE", f"/api/datasets/{dataset}?force=true"),
        ("DELETE", f"/api/datasets/{dataset}"),
        ("GET", "/api/runs"),
        ("GET", f"/api/runs/{run}/export?format=csv"),
        ("POST", f"/api/runs/{run}/cancel"),
        ("POST", "/api/datasets/simulate"),
        ("GET", "/api/me"),
        ("GET", "/api/health"),
        ("GET", "/openapi.json"),
        ("GET", "/datasets"),
        ("OPTIONS", "/api/datasets"),
    ]
    statuses: list[tuple[str, str, str, int]] = []
    with httpx.Client(base_url=server.base, timeout=10) as http:
        for host in hosts:
            headers = {"Host": host, "Origin": f"http://{host}"}
            for method, path in http_probes:
                body = {"scenario": "skf-sim1"} if method == "POST" else None
                response = http.request(method, path, headers=headers, json=body)
                statuses.append((host, method, path, response.status_code))
            for path in (f"/api/runs/{run}/stream", "/api/runs/999/stream"):
                code = _raw_handshake(port, path, host=host, origin=f"http://{host}")
                statuses.append((host, "WS", path, code))
    # a legitimate Host with a foreign page's Origin (cross-site WebSocket hijacking)
    for origin in (f"http://{ATTACKER}:{port}", "null"):
        code = _raw_handshake(
            port, f"/api/runs/{run}/stream", host=f"127.0.0.1:{port}", origin=origin
        )
        statuses.append((origin, "WS", "origin", code))
    assert len(statuses) >= 20
    refused = [s for s in statuses if s[3] == (403 if s[1] == "WS" else 400)]
    assert refused == statuses  # 100 % refused
    # and the real dashboard still works, its data untouched
    assert server.http.get(f"/api/datasets/{dataset}").status_code == 200
    own = f"http://127.0.0.1:{port}"
    assert (
        _raw_handshake(port, f"/api/runs/{run}/stream", host=f"127.0.0.1:{port}", origin=own) == 101
    )
    assert (
        _raw_handshake(port, f"/api/runs/{run}/stream", host=f"localhost:{port}", origin=None)
        == 101
    )


@pytest.mark.slow
def test_an_idle_keep_alive_connection_outlives_the_clients_pool_expiry(
    live: tuple[Server, int, int],
) -> None:
    """A connection idle for longer than httpx keeps one pooled (5 s) still answers: with
    uvicorn's default (also 5 s) the server could close it just as the client reused it, and
    the client got "server disconnected" on a request the server never read (a soak failure)."""
    server, _, run = live
    request = f"GET /api/runs/{run} HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n\r\n".encode()
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as s:
        for pause in (0.0, 6.0):
            time.sleep(pause)
            s.sendall(request)
            head = _read_response(s)
            assert head.startswith(b"HTTP/1.1 200"), head[:80]


def _read_response(s: socket.socket) -> bytes:
    """The head of one HTTP/1.1 response, its Content-Length body read past; b"" if the
    peer closed the connection first."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = s.recv(65536)
        if not chunk:
            return data
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    length = re.search(rb"(?i)content-length: *(\d+)", head)
    while length is not None and len(body) < int(length.group(1)):
        chunk = s.recv(65536)
        if not chunk:
            break
        body += chunk
    return head


@pytest.mark.slow
@pytest.mark.serial  # a 1 s bound on the close
def test_a_revoked_tokens_socket_is_closed_within_a_second(fresh_url) -> None:  # type: ignore[no-untyped-def]
    from websockets.asyncio.client import connect

    from app.db.engine import Database
    from app.services.tokens import TokenService

    url = fresh_url("sqlite")
    server = Server(url, env={"MAPWISE_REQUIRE_AUTH": "1"})
    db = Database(url)
    try:
        tokens = TokenService(db)
        _, writer = tokens.create("writer", ("read", "run"))
        watcher, secret = tokens.create("watcher", ("read",))
        _, other = tokens.create("other", ("read",))
        auth = {"Authorization": f"Bearer {writer}"}
        dataset = server.post(
            "/api/datasets", files={"file": ("log.csv", log_csv(600).encode())}, headers=auth
        )
        run = server.post("/api/runs", json=run_body(dataset.json()["id"]), headers=auth).json()

        async def scenario() -> tuple[int | None, str | None, bool]:
            base = f"{server.ws_base}/api/runs/{run['id']}/stream?token="
            async with connect(base + secret) as ws, connect(base + other) as bystander:
                assert '"full"' in str(await ws.recv())
                assert '"full"' in str(await bystander.recv())
                await asyncio.to_thread(tokens.revoke, watcher.id)
                await asyncio.wait_for(ws.wait_closed(), timeout=1.0)
                still_open = bystander.close_code is None
                return ws.close_code, ws.close_reason, still_open

        code, reason, bystander_open = asyncio.run(scenario())
        assert code == 1008
        assert reason == "the token was revoked"
        assert bystander_open  # only the revoked token's socket
    finally:
        db.dispose()
        server.stop()


@pytest.mark.slow
@pytest.mark.serial  # bounds the event-loop lag
def test_a_thousand_viewers_of_one_run_are_held_to_the_cap(fresh_url) -> None:  # type: ignore[no-untyped-def]
    """1000 viewers attempted on one streaming run, 50 handshakes at a time: exactly the
    cap (100) are served, the rest refused with 1013 and the reason; the API process grows
    by < 200 MB and its event loop never stalls 500 ms (health's worst lag of the last 30 s,
    read once start-up has left that window)."""
    import psutil
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    server = Server(fresh_url("sqlite"))
    try:
        dataset = server.post(
            "/api/datasets", files={"file": ("log.csv", log_csv(3000).encode())}
        ).json()
        run = server.post("/api/runs", json=run_body(dataset["id"], pace=1.0)).json()
        server.wait_run(run["id"], ("running",))
        _wait_for_a_quiet_loop(server)
        api = psutil.Process(server.process.pid)
        rss0 = api.memory_info().rss
        peak = [rss0]
        sampling = threading.Event()

        def sample() -> None:
            while not sampling.wait(0.05):
                peak.append(api.memory_info().rss)

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        url = f"{server.ws_base}/api/runs/{run['id']}/stream"

        async def scenario() -> tuple[int, list[tuple[int | None, str]]]:
            gate = asyncio.Semaphore(50)
            release = asyncio.Event()
            admitted = 0
            refused: list[tuple[int | None, str]] = []

            async def viewer() -> None:
                nonlocal admitted
                async with gate:
                    ws = await connect(url, open_timeout=30, max_queue=4)
                    try:
                        first = await asyncio.wait_for(ws.recv(), timeout=30)
                    except ConnectionClosed as closed:
                        rcvd = closed.rcvd
                        refused.append((rcvd.code, rcvd.reason) if rcvd else (None, ""))
                        return
                assert '"full"' in str(first)
                admitted += 1
                try:
                    await release.wait()  # stay connected (not reading) until the end
                finally:
                    await ws.close()

            tasks = [asyncio.create_task(viewer()) for _ in range(1000)]
            while admitted + len(refused) < 1000:
                done = [t for t in tasks if t.done() and t.exception() is not None]
                if done:
                    raise done[0].exception()  # type: ignore[misc]
                await asyncio.sleep(0.05)
            admitted_at_peak = admitted
            release.set()
            await asyncio.gather(*tasks)
            return admitted_at_peak, refused

        admitted, refused = asyncio.run(scenario())
        sampling.set()
        sampler.join()
        health = server.get("/api/health")
        server.post(f"/api/runs/{run['id']}/cancel")
    finally:
        server.stop()
    assert admitted == 100
    assert len(refused) == 900
    assert {code for code, _ in refused} == {1013}
    assert all("maximum of 100 viewers" in reason for _, reason in refused)
    grown_mb = (max(peak) - rss0) / 2**20
    assert grown_mb < 200, grown_mb
    # A handler that blocked the loop (a synchronous query, an encode per viewer) stalls it
    # for seconds under this burst; scheduling on a shared 2-core host alone costs up to
    # ~150 ms. How low the lag stays is a benchmark figure (scripts/bench_service.py).
    assert health["loop_lag_ms"] < 500, health
    print(f"RSS +{grown_mb:.1f} MB, loop lag {health['loop_lag_ms']} ms")


def _wait_for_a_quiet_loop(server: Server, timeout: float = 60.0) -> None:
    """Until health's lag window (30 s) no longer holds the start-up and the upload, so the
    lag read afterwards is the viewers' alone."""
    deadline = time.monotonic() + timeout
    while (lag := server.get("/api/health")["loop_lag_ms"]) >= 100:
        if time.monotonic() > deadline:
            raise AssertionError(f"the idle server's event loop lags {lag} ms (a loaded host?)")
        time.sleep(0.5)
