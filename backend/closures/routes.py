"""REST of the building modes: list (``watch``), close, reopen (``building_modes``,
backend/actions.py)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Request, status

from backend.actions import require_action
from backend.auth import Principal
from backend.closure import ClosureError, ClosureRequest
from backend.closures.service import ClosureService
from backend.rest.deps import Watcher
from backend.state import app_state

__all__ = ["router"]

router = APIRouter(prefix="/api/closures", tags=["building modes"])

Modes = Annotated[Principal, Depends(require_action("building_modes"))]


def _service(request: Request) -> ClosureService:
    service = app_state(request.app).closures
    if not isinstance(service, ClosureService):
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, "building modes not running")
    return service


@router.get("")
async def list_closures(request: Request, _: Watcher) -> dict[str, Any]:
    """Every closure (staff's, in force or planned, and trouble) and the nodes closed now."""
    return _service(request).view()


@router.post("", status_code=status.HTTP_201_CREATED)
async def close(request: Request, who: Modes, body: ClosureRequest) -> dict[str, Any]:
    """Close a gallery (``area``), ``nodes``, a ``door`` or an ``elevator``, now or between
    ``start`` and ``end`` (Unix seconds). 422 for an element the site does not have."""
    service = _service(request)
    try:
        closure = await service.add(body, by=who.name)
    except ClosureError as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None
    return closure.view(service.clock())


@router.delete("/{closure_id}")
async def reopen(request: Request, who: Modes, closure_id: str) -> dict[str, Any]:
    """Reopen (a trouble closure too: staff checked the door or the lift). 404 if unknown."""
    service = _service(request)
    try:
        closure = await service.remove(closure_id, by=who.name)
    except KeyError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no closure {closure_id!r}") from None
    return closure.view(service.clock())
