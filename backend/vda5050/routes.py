"""REST of the VDA 5050 master control: pause one vehicle and let it go on (docs/console.md,
"Robots"; docs/vda5050.md, "Pause")."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, Request, status

from backend.api.deps import Sites, Staff, Store, not_found
from backend.api.models import RequestBody

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["console"])

Name = Annotated[str, Path(max_length=64)]


class PauseRobot(RequestBody):
    paused: bool


@router.post("/robots/{name}/pause")
async def pause_robot(
    who: Staff, sites: Sites, db: Store, request: Request, name: Name, body: PauseRobot
) -> dict[str, Any]:
    """``startPause`` (paused true) or ``stopPause`` to a VDA 5050 vehicle: it stops where it
    stands, its order and task kept, until staff let it go on. A GuideBot robot has no pause
    of its own (409): pause the fleet, or cancel its task."""
    config = next((r for r in sites.site.robots if r.name == name), None)
    if config is None:
        raise not_found(f"robot {name!r}")
    if config.interface != "vda5050":
        raise HTTPException(
            status.HTTP_409_CONFLICT,
            f"{name} runs GuideBot's robot agent: one robot is paused only when it is a VDA "
            "5050 vehicle (pause the fleet, or cancel its task)",
        )
    master = getattr(request.app.state, "vda5050", None)
    robot = next((r for r in master.robots.values() if r.name == name), None) if master else None
    if robot is None:
        raise HTTPException(
            status.HTTP_409_CONFLICT, f"{name} is out of reach: no MQTT broker (--mqtt)"
        )
    if not robot.online:
        raise HTTPException(status.HTTP_409_CONFLICT, f"{name} is offline")
    await robot.pause(body.paused)
    kind = "robot_paused" if body.paused else "robot_resumed"
    db.record_event(kind, "console", {"robot": name, "by": who.name})
    return {"robot": name, "paused": body.paused}
