"""What keeps other sites out: the Host allowlist, the Content-Security-Policy, and the API
documentation pages behind the same token as the API (docs/security.md).

DNS rebinding: a page of ``attacker.example`` whose name the attacker re-points at
127.0.0.1 talks to a loopback server as its own origin, so neither CORS nor a same-origin
check can tell it apart. What it cannot change is the ``Host`` header, which carries the
attacker's name: :class:`TrustedHosts` refuses any name outside ``MAPWISE_ALLOWED_HOSTS``
(400 over HTTP, 403 at a WebSocket handshake) before anything else runs.
"""

from __future__ import annotations

import base64
import hashlib
import re

from fastapi import APIRouter, Depends, FastAPI, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse
from starlette._utils import parse_host_header
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.types import Receive, Scope, Send

from app.api.deps import require_token

# The dashboard's policy: its own scripts only (plus the hash of the inline import map, added
# per page), inline styles because Plotly writes <style> elements and style attributes,
# data:/blob: images for the favicon and Plotly's PNG export.
CSP_DIRECTIVES: dict[str, str] = {
    "default-src": "'self'",
    "script-src": "'self'",
    "style-src": "'self' 'unsafe-inline'",
    "img-src": "'self' data: blob:",
    "connect-src": "'self'",
    "object-src": "'none'",
    "base-uri": "'none'",
    "form-action": "'self'",
    "frame-ancestors": "'none'",
}
# Swagger UI and ReDoc come from their CDNs (as FastAPI serves them).
DOCS_SOURCES: dict[str, str] = {
    "script-src": "https://cdn.jsdelivr.net",
    "style-src": "https://cdn.jsdelivr.net https://fonts.googleapis.com",
    "img-src": "https://fastapi.tiangolo.com https://cdn.redoc.ly",
    "font-src": "https://fonts.gstatic.com",
    "worker-src": "blob:",
}
_INLINE_SCRIPT = re.compile(r"<script(?![^>]*\bsrc=)[^>]*>(.*?)</script>", re.S | re.I)


def content_security_policy(html: str | None = None, extra: dict[str, str] | None = None) -> str:
    """The policy, with the SHA-256 of each inline script of ``html`` allowed by hash."""
    directives = dict(CSP_DIRECTIVES)
    for name, sources in (extra or {}).items():
        directives[name] = directives.get(name, "'self'") + " " + sources
    if html is not None:
        hashes = [
            "'sha256-" + base64.b64encode(hashlib.sha256(m.encode()).digest()).decode() + "'"
            for m in _INLINE_SCRIPT.findall(html)
        ]
        if hashes:
            directives["script-src"] += " " + " ".join(hashes)
    return "; ".join(f"{name} {sources}" for name, sources in directives.items())


DEFAULT_CSP = content_security_policy()


class TrustedHosts(TrustedHostMiddleware):
    """Starlette's TrustedHostMiddleware (400 on an unknown Host), and at a WebSocket
    handshake a close before accepting, which the server answers with 403."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "websocket" or self.allow_any:
            await super().__call__(scope, receive, send)
            return
        host_header = dict(scope.get("headers", [])).get(b"host", b"").decode("latin-1")
        parsed = parse_host_header(host_header)
        host = parsed.host.lower() if parsed is not None else None
        if host is not None and any(
            host == p or (p.startswith("*") and host.endswith(p[1:])) for p in self.allowed_hosts
        ):
            await self.app(scope, receive, send)
            return
        await send({"type": "websocket.close", "code": 1008, "reason": "host not allowed"})


def docs_router(app: FastAPI) -> APIRouter:
    """``/openapi.json``, ``/docs`` and ``/redoc`` with the API's rule: a token (``read``)
    whenever the server requires one."""
    router = APIRouter(include_in_schema=False, dependencies=[Depends(require_token)])

    @router.get("/openapi.json")
    def openapi() -> JSONResponse:
        return JSONResponse(app.openapi())

    @router.get("/docs")
    def swagger(request: Request) -> HTMLResponse:
        return _docs_page(get_swagger_ui_html(openapi_url="/openapi.json", title=app.title))

    @router.get("/redoc")
    def redoc(request: Request) -> HTMLResponse:
        return _docs_page(get_redoc_html(openapi_url="/openapi.json", title=app.title))

    return router


def _docs_page(page: HTMLResponse) -> HTMLResponse:
    html = bytes(page.body).decode()
    policy = content_security_policy(html, DOCS_SOURCES)
    return HTMLResponse(html, headers={"Content-Security-Policy": policy})
