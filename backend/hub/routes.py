"""REST view of the hub for the admin GUI: who is connected, what they subscribe to."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request

from backend.actions import require_action
from backend.auth import Principal

from .core import HUB_NAME, Hub

__all__ = ["router"]

router = APIRouter(prefix="/api/hub", tags=["hub"])

Watcher = Annotated[Principal, Depends(require_action("watch"))]


@router.get("/clients")
async def list_clients(request: Request, _: Watcher) -> dict[str, Any]:
    """Connected WebSocket clients and in-process endpoints, with queue statistics."""
    hub: Hub = request.app.state.hub
    remote = [client.stats() for client in hub.clients.values()]
    local = sorted(n for n in hub.bus.endpoint_names if n not in hub.clients and n != HUB_NAME)
    return {
        "clients": remote,
        "modules": local,
        "published": hub.bus.published,
        "refused": hub.refused,
        "overflow_disconnects": hub.overflow_disconnects,
    }
