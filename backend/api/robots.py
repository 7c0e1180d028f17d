"""Robot routes: the fleet as the Task Manager sees it."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Request

from backend.api.deps import Requester, Staff, forbid, not_found, task_manager, traffic
from backend.auth import Role

__all__ = ["router"]

router = APIRouter(prefix="/api/robots", tags=["robots"])


def _view(request: Request, name: str) -> dict[str, Any]:
    info = task_manager(request).robots[name]
    return {**info.as_dict(), "areas": traffic(request).locks.held_by(name)}


@router.get("")
async def list_robots(request: Request, _: Staff) -> list[dict[str, Any]]:
    return [_view(request, name) for name in task_manager(request).robots]


@router.get("/{name}")
async def get_robot(
    request: Request, who: Requester, name: Annotated[str, Path(max_length=64)]
) -> dict[str, Any]:
    """Staff see any robot; a robot only itself."""
    if who.role is Role.PANEL or (who.role is Role.ROBOT and who.name != name):
        raise forbid("a robot may only see itself")
    if name not in task_manager(request).robots:
        raise not_found(f"robot {name!r}")
    return _view(request, name)
