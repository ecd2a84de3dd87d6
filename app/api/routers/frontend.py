"""The dashboard: ``frontend/index.html`` for every view route, static files under
``/static/``, Plotly from the installed ``plotly`` package (no CDN, works offline).

Any other ``GET``/``HEAD`` outside ``/api/`` and ``/static/`` also gets the page, whose
router shows its own "Page not found" view: a person who mistypes an address sees the
dashboard, not a JSON error. Unknown ``/api/`` paths stay JSON 404s for programs."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

from fastapi import APIRouter, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from fastapi.routing import APIRoute
from starlette.routing import Match
from starlette.staticfiles import StaticFiles
from starlette.types import Scope

from app.api.security import content_security_policy
from app.errors import NotFoundError
from app.resources import resource_dir

FRONTEND_DIR = resource_dir("frontend")
VIEW_ROUTES = (
    "/datasets",
    "/runs/new",
    "/runs/{run_id}",
    "/compare",
    "/versions",
    "/sweeps",
    "/sweeps/{sweep_id}",
    "/batches",
    "/batches/{batch_id}",
    "/ecus",
    "/ecus/{ecu_id}",
)
NO_CACHE = {"Cache-Control": "no-cache"}  # revalidate (ETag) so browsers never run stale code
IMMUTABLE = {"Cache-Control": "public, max-age=31536000, immutable"}
PLOTLY_URL = "/static/vendor/plotly.min.js"

router = APIRouter(include_in_schema=False)


def plotly_js() -> Path | None:
    try:
        import plotly
    except ImportError:
        return None
    path = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
    return path if path.is_file() else None


class RevalidatingStatic(StaticFiles):
    """Hashed URLs (``?v=``) are immutable; anything else is revalidated on every use."""

    async def get_response(self, path: str, scope: Scope) -> Response:
        response = await super().get_response(path, scope)
        hashed = b"v=" in scope.get("query_string", b"")
        response.headers.update(IMMUTABLE if hashed and response.status_code == 200 else NO_CACHE)
        return response


@router.get("/")
def root() -> RedirectResponse:
    return RedirectResponse("/datasets", status_code=307)


@router.head("/")
def root_head() -> Response:
    """``HEAD /`` answers 200 with the dashboard's headers: uptime probes and load
    balancers ask the root with ``HEAD`` and do not follow redirects."""
    return _index()


def asset_versions(root: Path = FRONTEND_DIR) -> dict[str, str]:
    """``/static/<path>`` → ``/static/<path>?v=<content hash>`` for every JS and CSS file."""
    out = {}
    for path in sorted(root.rglob("*")):
        if path.suffix in (".js", ".css") and path.is_file():
            digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12]
            url = "/static/" + path.relative_to(root).as_posix()
            out[url] = f"{url}?v={digest}"
    bundle = plotly_js()
    if bundle is not None:
        import plotly

        out[PLOTLY_URL] = f"{PLOTLY_URL}?v={plotly.__version__}"
    return out


def render_index(html: str, versions: dict[str, str]) -> str:
    """Content-hashed asset URLs: the import map sends every module import to its hashed
    URL, and the page's own ``/static/…`` references get theirs, so a browser never runs a
    stale module (hashed URLs are cached for good, the page itself is revalidated)."""
    modules = {
        url: hashed
        for url, hashed in versions.items()
        if url.endswith(".js") and url != PLOTLY_URL  # Plotly is a classic script
    }
    importmap = json.dumps({"imports": modules}, separators=(",", ":"))
    html = re.sub(
        r'<script type="importmap">.*?</script>',
        lambda _m: f'<script type="importmap">{importmap}</script>',
        html,
        count=1,
        flags=re.S,
    )
    return re.sub(
        r'(src|href)="(/static/[^"?#]+)"',
        lambda m: f'{m[1]}="{versions.get(m[2], m[2])}"',
        html,
    )


def _index() -> HTMLResponse:
    index = FRONTEND_DIR / "index.html"
    if not index.is_file():
        raise NotFoundError("the dashboard is not installed (frontend/index.html is missing)")
    html = render_index(index.read_text(encoding="utf-8"), asset_versions())
    # The import map is an inline script: the policy allows it by its hash, nothing else.
    return HTMLResponse(
        html, headers=NO_CACHE | {"Content-Security-Policy": content_security_policy(html)}
    )


for _route in VIEW_ROUTES:
    router.add_api_route(_route, _index, methods=["GET", "HEAD"], include_in_schema=False)


@router.get(PLOTLY_URL)
def plotly_bundle(request: Request) -> FileResponse:
    path = plotly_js()
    if path is None:
        raise NotFoundError("the plotly package is not installed")
    headers = IMMUTABLE if "v" in request.query_params else NO_CACHE
    return FileResponse(path, media_type="text/javascript", headers=headers)


def static_files() -> RevalidatingStatic | None:
    """``frontend/`` as ``/static`` (``None`` until the frontend exists)."""
    if not FRONTEND_DIR.is_dir():
        return None
    return RevalidatingStatic(directory=FRONTEND_DIR, check_dir=False)


class DashboardFallback(APIRoute):
    """Matches only ``GET``/``HEAD`` of a path outside ``/api`` and ``/static``; anything
    else falls through (to a JSON 404, or a 405 from the route it partly matched), so no
    API answer changes."""

    def matches(self, scope: Scope) -> tuple[Match, Scope]:
        path = scope.get("path", "")
        if (
            scope["type"] != "http"
            or scope.get("method") not in ("GET", "HEAD")
            or path in ("/api", "/static")
            or path.startswith(("/api/", "/static/"))
        ):
            return Match.NONE, {}
        return super().matches(scope)


def _fallback(path: str) -> HTMLResponse:
    return _index()


# Last in this router; the app includes the router after every API router.
router.add_api_route(
    "/{path:path}",
    _fallback,
    methods=["GET", "HEAD"],
    include_in_schema=False,
    route_class_override=DashboardFallback,
)
