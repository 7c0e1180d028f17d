"""The staff alerts active now (a page's sign-in check is GET /api/me, backend/api/web.py)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from backend.api.deps import Staff

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["session"])


@router.get("/alerts")
async def list_alerts(request: Request, _: Staff) -> list[dict[str, Any]]:
    """The active staff alerts (``staff_alert`` payloads, docs/messages.md), oldest first; a
    console loads these, then follows ``staff_alert`` on the hub."""
    board = request.app.state.alerts
    return sorted(board.active.values(), key=lambda a: a["at"])
