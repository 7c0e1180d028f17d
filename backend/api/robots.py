"""Robot routes: the fleet as the Task Manager sees it."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Request

from backend.auth import Role
from backend.rest.deps import SeeRobot, Tasks, Traffic, Watcher, forbid, not_found
from backend.state import app_state
from backend.tasks.manager import TaskManager
from backend.traffic.manager import TrafficManager

__all__ = ["router"]

router = APIRouter(prefix="/api/robots", tags=["robots"])


def _view(
    request: Request, manager: TaskManager, traffic: TrafficManager, name: str
) -> dict[str, Any]:
    info = manager.robots[name]
    robocan = app_state(request.app).robocan
    return {
        **info.as_dict(),
        "areas": traffic.locks.held_by(name),
        "robocan": robocan.view(name) if robocan is not None else None,
    }


@router.get("")
async def list_robots(
    request: Request, _: Watcher, manager: Tasks, traffic: Traffic
) -> list[dict[str, Any]]:
    """Every robot, with its last ``robocan_status`` (``robocan``, null if none came)."""
    return [_view(request, manager, traffic, name) for name in manager.robots]


@router.get("/{name}")
async def get_robot(
    request: Request,
    who: SeeRobot,
    manager: Tasks,
    traffic: Traffic,
    name: Annotated[str, Path(max_length=64)],
) -> dict[str, Any]:
    """Staff see any robot; a robot only itself."""
    if who.role is Role.ROBOT and who.name != name:
        raise forbid("a robot may only see itself")
    if name not in manager.robots:
        raise not_found(f"robot {name!r}")
    return _view(request, manager, traffic, name)
