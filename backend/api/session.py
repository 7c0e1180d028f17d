"""Who am I (a console's sign-in check) and the staff alerts active now."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from backend.api.deps import Anyone, Staff

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["session"])


@router.get("/whoami")
async def whoami(who: Anyone) -> dict[str, str]:
    """The name and role of the token: a page signs in by calling this (failed attempts are
    limited per address: 429 with Retry-After)."""
    return {"name": who.name, "role": who.role.value}


@router.get("/alerts")
async def list_alerts(request: Request, _: Staff) -> list[dict[str, Any]]:
    """The active staff alerts (``staff_alert`` payloads, docs/messages.md), oldest first; a
    console loads these, then follows ``staff_alert`` on the hub."""
    board = request.app.state.alerts
    return sorted(board.active.values(), key=lambda a: a["at"])
