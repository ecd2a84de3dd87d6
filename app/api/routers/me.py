"""``GET /api/me``: what the caller may do, so the dashboard hides what it cannot."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field

from app.api.deps import CallerDep
from app.api.schemas import ERRORS

router = APIRouter(tags=["auth"], responses=ERRORS)


class MeOut(BaseModel):
    auth_required: bool = Field(description="Whether this server asks for bearer tokens.")
    token_id: int | None = Field(description="The caller's token (null with auth off).")
    scopes: list[str] = Field(description="What the caller may do: read, run, admin.")


@router.get("/me", response_model=MeOut)
def me(caller: CallerDep) -> MeOut:
    """The caller's scopes: every scope when auth is off (loopback without tokens)."""
    return MeOut(
        auth_required=caller.auth_required, token_id=caller.token_id, scopes=list(caller.scopes)
    )
