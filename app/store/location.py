"""Where the artifact store lives: ``MAPWISE_STORE_URL``, a directory or an fsspec URL.

A plain path (the default ``./mapwise-data/``) is resolved against the working directory
when the settings are read, as the default SQLite database ``./mapwise.db`` is, and becomes
a ``file://`` URL; a URL keeps its scheme (``file://``, ``memory://``, ``s3://`` …) and must
name a filesystem fsspec can open here (``s3://`` needs the ``s3fs`` package).
"""

from __future__ import annotations

import os
from pathlib import Path

import fsspec

DEFAULT_STORE_URL = "./mapwise-data/"
STORE_URL_ENV = "MAPWISE_STORE_URL"


def resolve_store_url(value: str | None) -> str:
    """The store's absolute URL: a path becomes ``file:///abs/path``; ValueError for a
    scheme fsspec does not know (or whose package is not installed)."""
    value = (value or "").strip() or DEFAULT_STORE_URL
    if "://" not in value:
        return Path(value).expanduser().absolute().as_uri()
    protocol = value.split("://", 1)[0]
    try:
        fsspec.get_filesystem_class(protocol)
    except ValueError as exc:
        raise ValueError(f"unknown store URL scheme {protocol!r} in {value!r}") from exc
    except ImportError as exc:
        raise ValueError(f"a {protocol}:// store needs a package not installed: {exc}") from exc
    return value


def redacted(url: str) -> str:
    """``url`` without the credentials of its authority (``sftp://user:pw@host`` → ``sftp://host``),
    for messages and logs."""
    scheme, sep, rest = url.partition("://")
    if not sep:
        return url
    authority, slash, path = rest.partition("/")
    return f"{scheme}://{authority.rpartition('@')[2]}{slash}{path}"


def default_store_url() -> str:
    """The store a process uses without settings: ``MAPWISE_STORE_URL``, else the default."""
    return resolve_store_url(os.environ.get(STORE_URL_ENV))
