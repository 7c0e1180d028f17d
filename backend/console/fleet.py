"""REST routes of the console's fleet controls for a busy day: pause the whole fleet and
resume, send every robot home, open a door or call an elevator by hand. Each is logged in the
event log with who did it (docs/console.md, "Fleet")."""

from __future__ import annotations

import time
from typing import Annotated, Any

from fastapi import APIRouter, Body, HTTPException, Path, Request, status
from pydantic import BaseModel, ConfigDict, Field

from backend.console.feed import ConsoleFeed
from backend.console.routes import Feed
from backend.db.store import DbStore
from backend.rest.deps import Sites, Staff, Store, Tasks, Watcher, not_found
from backend.site.service import SiteService
from backend.state import app_state
from backend.tasks.manager import TaskManager
from backend.tasks.model import TaskError
from guidebot.payloads.building import CallElevator, OpenDoor, ReleaseDoor

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["console"])

Name = Annotated[str, Path(max_length=64)]
HOME_PRIORITY = 10
"""As "Send to charge" in the Robots view."""


class Pause(BaseModel):
    model_config = ConfigDict(extra="forbid")
    reason: str = Field(default="", max_length=200)


class Call(BaseModel):
    model_config = ConfigDict(extra="forbid")
    floor: str = Field(min_length=1, max_length=64)


def _fleet_view(request: Request, manager: TaskManager) -> dict[str, Any]:
    """The Task Manager says whether it is paused; who paused it, when and why is kept here."""
    state: dict[str, Any] = (app_state(request.app).fleet_pause or {}) if manager.paused else {}
    return {
        "paused": bool(manager.paused),
        "by": state.get("by"),
        "since": state.get("since"),
        "reason": state.get("reason", ""),
    }


@router.get("/fleet")
async def fleet_state(request: Request, _: Watcher, manager: Tasks) -> dict[str, Any]:
    """Whether the fleet is paused, since when, by whom and why."""
    return _fleet_view(request, manager)


@router.post("/fleet/pause")
async def pause_fleet(
    request: Request,
    who: Staff,
    manager: Tasks,
    db: Store,
    body: Annotated[Pause | None, Body()] = None,
) -> dict[str, Any]:
    """No robot is given a task (queued tasks wait, idle robots stay where they are) until
    staff resume; running tasks go on. Not kept across a server restart."""
    reason = (body or Pause()).reason
    if not manager.paused:
        manager.set_paused(True)
        request.app.state.fleet_pause = {"by": who.name, "since": time.time(), "reason": reason}
        db.record_event("fleet_paused", "console", {"by": who.name, "reason": reason})
    return _fleet_view(request, manager)


@router.post("/fleet/resume")
async def resume_fleet(request: Request, who: Staff, manager: Tasks, db: Store) -> dict[str, Any]:
    """Dispatch again: queued tasks go to free robots at once."""
    if manager.paused:
        request.app.state.fleet_pause = None
        db.record_event("fleet_resumed", "console", {"by": who.name})
        manager.set_paused(False)
    return _fleet_view(request, manager)


@router.post("/fleet/home")
async def send_fleet_home(who: Staff, manager: Tasks, db: Store) -> dict[str, Any]:
    """Every online robot in service gets a charge task pinned to it (a free charging
    station; priority 10): one without a task goes at once, one on a tour after it."""
    sent: list[dict[str, str]] = []
    skipped: list[dict[str, str]] = []
    for name, robot in sorted(manager.robots.items()):
        if not robot.online:
            skipped.append({"robot": name, "why": "offline"})
        elif robot.out_of_service:
            skipped.append({"robot": name, "why": "out of service"})
        else:
            try:
                task = manager.request(
                    "charge", {}, priority=HOME_PRIORITY, requester=who.name, robot=name
                )
            except TaskError as exc:
                skipped.append({"robot": name, "why": str(exc)})
                continue
            sent.append({"robot": name, "task_id": task.id})
    db.record_event(
        "fleet_sent_home", "console", {"by": who.name, "robots": [s["robot"] for s in sent]}
    )
    return {"sent": sent, "skipped": skipped}


@router.post("/robots/{name}/charge", status_code=status.HTTP_201_CREATED)
async def send_to_charge(who: Staff, manager: Tasks, db: Store, name: Name) -> dict[str, Any]:
    """Send one robot to charge (a charge task pinned to it, priority 10): at the station it
    stands at, else the nearest free one; a robot on a tour goes after it (docs/console.md,
    "Fleet"; backend/tasks/manager.py, ``send_to_charge``)."""
    robot = manager.robots.get(name)
    if robot is None:
        raise not_found(f"robot {name!r}")
    if not robot.online:
        raise HTTPException(status.HTTP_409_CONFLICT, f"{name} is offline")
    task = manager.send_to_charge(name, by=who.name, priority=HOME_PRIORITY)
    station = task.params.get("station")
    db.record_event(
        "robot_sent_to_charge", "console", {"robot": name, "station": station, "by": who.name}
    )
    return {"robot": name, "station": station, "task_id": task.id}


def _building(request: Request) -> Any:
    building = app_state(request.app).building
    if building is None:
        raise HTTPException(status.HTTP_409_CONFLICT, "the building interface is off")
    return building


@router.post("/building/doors/{door}/open", status_code=status.HTTP_202_ACCEPTED)
async def open_door(
    request: Request, who: Staff, service: Sites, feed: Feed, db: Store, door: Name
) -> dict[str, Any]:
    """Open a door by hand: the building holds it open for the console until "close" or
    the door's longest hold (``max_hold_s``). Its state shows in door_opened/door_closed; a
    door that does not open raises the building_command_failed alert."""
    return _door_by_hand(request, service, feed, db, OpenDoor(door=door), by=who.name)


@router.post("/building/doors/{door}/close", status_code=status.HTTP_202_ACCEPTED)
async def close_door(
    request: Request, who: Staff, service: Sites, feed: Feed, db: Store, door: Name
) -> dict[str, Any]:
    """Let go of a door opened by hand (it closes unless a robot holds it too)."""
    return _door_by_hand(request, service, feed, db, ReleaseDoor(door=door), by=who.name)


def _door_by_hand(
    request: Request,
    service: SiteService,
    feed: ConsoleFeed,
    db: DbStore,
    command: OpenDoor | ReleaseDoor,
    *,
    by: str,
) -> dict[str, Any]:
    """Ask the building for ``command`` on a door of the site, logged with who asked."""
    if not any(d.id == command.door for d in service.site.doors):
        raise not_found(f"door {command.door!r}")
    _building(request)
    feed.endpoint.publish(command)
    kind = "door_opened_by_hand" if isinstance(command, OpenDoor) else "door_released_by_hand"
    db.record_event(kind, "console", {"door": command.door, "by": by})
    return {"door": command.door, "by": by}


@router.post("/building/elevators/{elevator}/call", status_code=status.HTTP_202_ACCEPTED)
async def call_elevator(
    request: Request,
    who: Staff,
    service: Sites,
    feed: Feed,
    db: Store,
    elevator: Name,
    body: Annotated[Call, Body()],
) -> dict[str, Any]:
    """Call an elevator's car to a floor by hand; elevator_in_position says when it is there."""
    lift = next((e for e in service.site.elevators if e.id == elevator), None)
    if lift is None:
        raise not_found(f"elevator {elevator!r}")
    floors = [s.floor for s in lift.stops]
    if body.floor not in floors:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"elevator {elevator} has no stop on floor {body.floor!r} (it stops at "
            f"{', '.join(floors)})",
        )
    _building(request)
    feed.endpoint.publish(CallElevator(elevator=elevator, floor=body.floor))
    db.record_event(
        "elevator_called_by_hand",
        "console",
        {"elevator": elevator, "floor": body.floor, "by": who.name},
    )
    return {"elevator": elevator, "floor": body.floor, "by": who.name}
