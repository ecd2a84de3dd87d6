"""The HTTP API (FastAPI): app factory, routers, schemas."""

from app.api.app import create_app

__all__ = ["create_app"]
