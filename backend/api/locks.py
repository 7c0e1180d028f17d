"""Area lock routes: what staff see and the one thing they may do (force a release)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Request

from backend.auth import Role
from backend.rest.deps import Staff, Traffic, Watcher, forbid, not_found

__all__ = ["router"]

router = APIRouter(prefix="/api/locks", tags=["locks"])


@router.get("")
async def list_locks(_: Watcher, traffic: Traffic) -> list[dict[str, Any]]:
    """Every restricted area: free, held, holder_offline (kept: it may be inside) or yielding."""
    return [
        {
            "area": v.area,
            "state": v.state.value,
            "holder": v.holder,
            "since": v.since,
            "entered": v.entered,
            "waiting": v.waiting,
        }
        for v in traffic.lock_views()
    ]


@router.post("/{area}/release")
async def force_release(
    request: Request, who: Staff, manager: Traffic, area: Annotated[str, Path(max_length=64)]
) -> dict[str, Any]:
    """Release an area by hand, e.g. its robot is offline and staff saw it is outside.

    Operators may release only a lock whose holder is offline; admins any lock."""
    if area not in manager.locks.areas:
        raise not_found(f"area {area!r}")
    view = next(v for v in manager.lock_views() if v.area == area)
    if who.role is Role.OPERATOR and view.state.value != "holder_offline":
        raise forbid(
            f"area {area!r} is {view.state.value}: operators may release only a lock whose "
            "holder is offline (admins may release any)"
        )
    holder = manager.force_release(area, by=who.name)
    request.app.state.console.schedule_lock_diff()
    return {"area": area, "released_from": holder}
