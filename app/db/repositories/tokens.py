"""API bearer tokens (only their hashes are stored)."""

from __future__ import annotations

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from app.db.models import ApiTokenRow, utcnow
from app.db.repositories.base import from_row
from app.domain import SCOPES, ApiToken
from app.errors import NotFoundError


def _token(row: ApiTokenRow) -> ApiToken:
    scopes = tuple(s for s in SCOPES if s in row.scopes.split(","))
    return from_row(ApiToken, row, scopes=scopes)


class TokenRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def add(self, *, name: str, prefix: str, token_hash: str, scopes: tuple[str, ...]) -> ApiToken:
        row = ApiTokenRow(name=name, prefix=prefix, token_hash=token_hash, scopes=",".join(scopes))
        self.s.add(row)
        self.s.flush()
        return _token(row)

    def list(self) -> list[ApiToken]:
        return [_token(r) for r in self.s.scalars(select(ApiTokenRow).order_by(ApiTokenRow.id))]

    def revoke(self, token_id: int) -> ApiToken:
        row = self.s.get(ApiTokenRow, token_id)
        if row is None:
            raise NotFoundError(f"token {token_id} does not exist", field="token_id")
        if row.revoked_at is None:
            row.revoked_at = utcnow()
        self.s.flush()
        return _token(row)

    def active_by_hash(self, token_hash: str) -> ApiToken | None:
        q = select(ApiTokenRow).where(
            ApiTokenRow.token_hash == token_hash, ApiTokenRow.revoked_at.is_(None)
        )
        row = self.s.scalars(q).first()
        return None if row is None else _token(row)

    def active_ids(self, token_ids: list[int]) -> set[int]:
        """Those of ``token_ids`` that still exist and are not revoked."""
        q = select(ApiTokenRow.id).where(
            ApiTokenRow.id.in_(token_ids), ApiTokenRow.revoked_at.is_(None)
        )
        return set(self.s.scalars(q))

    def touch(self, token_id: int) -> None:
        self.s.execute(
            update(ApiTokenRow).where(ApiTokenRow.id == token_id).values(last_used_at=utcnow())
        )
