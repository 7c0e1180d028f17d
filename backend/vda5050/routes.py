"""REST of the VDA 5050 master control: pause one vehicle and let it go on (docs/console.md,
"Robots"; docs/vda5050.md, "Pause"), send a 3.x vehicle to hibernate and wake it
(docs/vda5050.md, "Hibernation")."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, Request, status

from backend.rest.deps import Sites, Staff, Store, not_found
from backend.rest.models import RequestBody
from backend.state import app_state

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["console"])

Name = Annotated[str, Path(max_length=64)]


class PauseRobot(RequestBody):
    paused: bool


class HibernateRobot(RequestBody):
    hibernating: bool


def _vehicle(sites: Any, request: Request, name: str, instead: str) -> Any:
    """The master control's robot ``name`` (404 unknown, 409 not a VDA 5050 vehicle or no
    broker)."""
    config = next((r for r in sites.site.robots if r.name == name), None)
    if config is None:
        raise not_found(f"robot {name!r}")
    if config.interface != "vda5050":
        raise HTTPException(
            status.HTTP_409_CONFLICT,
            f"{name} runs GuideBot's robot agent: {instead}",
        )
    master = app_state(request.app).vda5050
    robot = next((r for r in master.robots.values() if r.name == name), None) if master else None
    if robot is None:
        raise HTTPException(
            status.HTTP_409_CONFLICT, f"{name} is out of reach: no MQTT broker (--mqtt)"
        )
    return robot


@router.post("/robots/{name}/pause")
async def pause_robot(
    who: Staff, sites: Sites, db: Store, request: Request, name: Name, body: PauseRobot
) -> dict[str, Any]:
    """``startPause`` (paused true) or ``stopPause`` to a VDA 5050 vehicle: it stops where it
    stands, its order and task kept, until staff let it go on. A GuideBot robot has no pause
    of its own (409): pause the fleet, or cancel its task."""
    robot = _vehicle(
        sites,
        request,
        name,
        "one robot is paused only when it is a VDA 5050 vehicle (pause the fleet, or cancel "
        "its task)",
    )
    if not robot.online:
        raise HTTPException(status.HTTP_409_CONFLICT, f"{name} is offline")
    await robot.pause(body.paused)
    kind = "robot_paused" if body.paused else "robot_resumed"
    db.record_event(kind, "console", {"robot": name, "by": who.name})
    return {"robot": name, "paused": body.paused}


@router.post("/robots/{name}/hibernate")
async def hibernate_robot(
    who: Staff, sites: Sites, db: Store, request: Request, name: Name, body: HibernateRobot
) -> dict[str, Any]:
    """``startHibernation`` (hibernating true) or ``stopHibernation`` to a VDA 5050 3.x
    vehicle (docs/vda5050.md, "Hibernation"): asleep it gets no task; a vehicle on a task is
    not sent to sleep (cancel the task first)."""
    robot = _vehicle(sites, request, name, "only a VDA 5050 3.x vehicle hibernates")
    if not robot.v3:
        raise HTTPException(
            status.HTTP_409_CONFLICT,
            f"{name} speaks VDA 5050 {robot.vehicle.version}: hibernation is 3.0.0",
        )
    if body.hibernating and not robot.online:
        raise HTTPException(status.HTTP_409_CONFLICT, f"{name} is not online")
    if body.hibernating and robot.task_id is not None:
        raise HTTPException(
            status.HTTP_409_CONFLICT, f"{name} runs task {robot.task_id}: cancel it first"
        )
    if not body.hibernating and not robot.hibernating:
        raise HTTPException(status.HTTP_409_CONFLICT, f"{name} is not hibernating")
    await robot.hibernate(body.hibernating)
    db.record_event(
        "robot_hibernation", "console", {"robot": name, "by": who.name, "asleep": body.hibernating}
    )
    return {"robot": name, "hibernating": body.hibernating}
