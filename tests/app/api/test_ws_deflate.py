"""``MAPWISE_WS_DEFLATE``: the live stream offers permessage-deflate only when asked to.

Against a real ``mapwise serve``: the client (websockets) offers the extension on every
handshake, and the server's answer says whether it took it."""

from __future__ import annotations

import pytest
from websockets.sync.client import connect

from tests.support.server import Server

pytestmark = pytest.mark.slow  # two real servers


@pytest.mark.parametrize(("setting", "negotiated"), [(None, False), ("true", True)])
def test_deflate_is_negotiated_only_when_configured(
    fresh_url,  # type: ignore[no-untyped-def]
    setting: str | None,
    negotiated: bool,
) -> None:
    env = {} if setting is None else {"MAPWISE_WS_DEFLATE": setting}
    server = Server(fresh_url("sqlite"), workers=1, env=env)
    try:
        url = f"{server.ws_base}/api/runs/1/stream"  # no such run: the handshake is enough
        with connect(url, open_timeout=30) as ws:
            extensions = ws.response.headers.get("Sec-WebSocket-Extensions", "")
            ws.recv(timeout=30)  # the error frame: run 1 does not exist
    finally:
        server.stop()
    assert ("permessage-deflate" in extensions) is negotiated, extensions
