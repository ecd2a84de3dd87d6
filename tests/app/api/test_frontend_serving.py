"""The dashboard is served by the app: view routes give the page with content-hashed asset
URLs, static files are cached by hash, Plotly comes from the installed package."""

from __future__ import annotations

import json
import re

import pytest
from fastapi.testclient import TestClient

from app.api.routers.frontend import FRONTEND_DIR
from app.resources import resource_dir


def test_the_dashboard_is_installed() -> None:
    """The dashboard ships with the app: a missing page is a failure, not a skip."""
    frontend = resource_dir("frontend")
    assert frontend == FRONTEND_DIR
    assert (frontend / "index.html").is_file(), f"{frontend}/index.html is missing"
    assert (frontend / "js" / "main.js").is_file()
    assert (frontend / "css" / "app.css").is_file()


@pytest.mark.parametrize(
    "route",
    ["/datasets", "/runs/new", "/runs/12", "/compare", "/versions", "/sweeps", "/sweeps/3",
     "/batches", "/batches/4"],
)  # fmt: skip
def test_view_routes_serve_the_page_with_hashed_assets(client: TestClient, route: str) -> None:
    response = client.get(route)
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/html")
    assert response.headers["cache-control"] == "no-cache"
    html = response.text
    found = re.search(r'<script type="importmap">(.*?)</script>', html, flags=re.S)
    assert found is not None
    imports = json.loads(found[1])["imports"]
    assert "/static/js/main.js" in imports
    assert all(re.fullmatch(r"\S+\?v=[0-9a-f]{12}", url) for url in imports.values())
    for url in re.findall(r'(?:src|href)="(/static/[^"]+)"', html):
        assert "?v=" in url, url


def test_hashed_static_files_are_immutable(client: TestClient) -> None:
    html = client.get("/datasets").text
    main = json.loads(re.search(r'type="importmap">(.*?)</script>', html, flags=re.S)[1])[
        "imports"
    ]["/static/js/main.js"]
    hashed = client.get(main)
    assert hashed.status_code == 200
    assert "immutable" in hashed.headers["cache-control"]
    plain = client.get("/static/js/main.js")
    assert plain.headers["cache-control"] == "no-cache"
    assert plain.content == hashed.content
    assert client.get("/static/nope.js").status_code == 404


def test_root_redirects_and_plotly_is_local(client: TestClient) -> None:
    response = client.get("/", follow_redirects=False)
    assert response.status_code in (302, 307)
    assert response.headers["location"] == "/datasets"
    plotly = client.get("/static/vendor/plotly.min.js")
    assert plotly.status_code == 200
    assert plotly.headers["content-type"].startswith("text/javascript")
    assert len(plotly.content) > 1_000_000


def test_every_module_is_preloaded_at_its_hashed_url(client: TestClient) -> None:
    """index.html lists every module for ``modulepreload`` (one fetch wave on a cold cache
    instead of one per import level); the list must follow the files."""
    html = client.get("/datasets").text
    imports = json.loads(re.search(r'type="importmap">(.*?)</script>', html, flags=re.S)[1])[
        "imports"
    ]
    preloaded = set(re.findall(r'<link rel="modulepreload" href="([^"]+)">', html))
    modules = {
        "/static/" + p.relative_to(FRONTEND_DIR).as_posix()
        for p in (FRONTEND_DIR / "js").rglob("*.js")
    } - {"/static/js/main.js"}
    assert preloaded == {imports[m] for m in modules}
    assert re.search(r'<link rel="preload" href="/static/vendor/plotly\.min\.js\?v=[^"]+"', html)
