"""API tokens: created once (the secret is shown only then), stored as a SHA-256 hash, each
with its scopes (``read``, ``run``, ``admin``; docs/security.md)."""

from __future__ import annotations

import hashlib
import secrets
from datetime import UTC, datetime, timedelta

from app.db.engine import Database
from app.db.repositories import TokenRepo
from app.domain import DEFAULT_SCOPES, SCOPES, ApiToken
from app.errors import InvalidRequestError

TOKEN_PREFIX = "mw_"
TOUCH_EVERY = timedelta(seconds=60)  # last-use is recorded at most this often


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


class TokenService:
    def __init__(self, db: Database) -> None:
        self.db = db

    def create(
        self, name: str, scopes: tuple[str, ...] | list[str] = DEFAULT_SCOPES
    ) -> tuple[ApiToken, str]:
        """A new token with ``scopes`` (default ``read`` and ``run``: ``admin`` is asked for)."""
        unknown = sorted(set(scopes) - set(SCOPES))
        if unknown or not scopes:
            raise InvalidRequestError(
                f"unknown scope {unknown[0]!r}; scopes are {', '.join(SCOPES)}"
                if unknown
                else f"a token needs at least one scope of {', '.join(SCOPES)}",
                field="scopes",
            )
        secret = TOKEN_PREFIX + secrets.token_urlsafe(32)
        with self.db.write() as s:
            token = TokenRepo(s).add(
                name=name.strip()[:200] or "token",
                prefix=secret[:10],
                token_hash=hash_token(secret),
                scopes=tuple(x for x in SCOPES if x in scopes),
            )
        return token, secret

    def list(self) -> list[ApiToken]:
        with self.db.read() as s:
            return TokenRepo(s).list()

    def revoke(self, token_id: int) -> ApiToken:
        with self.db.write() as s:
            return TokenRepo(s).revoke(token_id)

    def active_ids(self, token_ids: list[int]) -> set[int]:
        """Those of ``token_ids`` still active (the others were revoked or deleted)."""
        if not token_ids:
            return set()
        with self.db.read() as s:
            return TokenRepo(s).active_ids(token_ids)

    def verify(self, secret: str) -> ApiToken | None:
        """The active token with this secret (its last use recorded), else ``None``."""
        if not secret.startswith(TOKEN_PREFIX):
            return None
        with self.db.read() as s:
            token = TokenRepo(s).active_by_hash(hash_token(secret))
        now = datetime.now(UTC)
        if token is not None and (
            token.last_used_at is None or now - token.last_used_at > TOUCH_EVERY
        ):
            with self.db.write() as s:
                TokenRepo(s).touch(token.id)
        return token
