"""REST routes of the staff console: alerts, robots in or out of service, Petri nets (library,
running instances, kill) and the building simulator's inputs (buttons, fire alarm inputs)."""

from __future__ import annotations

import logging
from typing import Annotated, Any

import httpx
from fastapi import APIRouter, Body, Depends, HTTPException, Path, Query, Request, status
from pydantic import Field

from backend.alerts import AlertNotFound, AlertStore
from backend.console.feed import ConsoleFeed
from backend.rest.deps import (
    NetKiller,
    NetReader,
    Sites,
    Staff,
    Tasks,
    Watcher,
    app_service,
    error_response,
    not_found,
)
from backend.rest.models import RequestBody
from backend.tasks.model import TaskNotFound
from petri_nets.layout import doc_drawing
from petri_nets.library import UnknownNet

__all__ = ["router"]

log = logging.getLogger(__name__)

router = APIRouter(prefix="/api", tags=["console"])

Name = Annotated[str, Path(max_length=64)]


class Service(RequestBody):
    out_of_service: bool


class Kill(RequestBody):
    target: str = Field(min_length=1, max_length=64)
    """A robot name, or "rgm" for the server's own nets."""
    instance_id: str = Field(min_length=1, max_length=64)


class Press(RequestBody):
    button: str = Field(min_length=1, max_length=64)
    ms: float = Field(default=300.0, gt=0, le=10_000)


class SimulatedAlarm(RequestBody):
    alarm: str = Field(min_length=1, max_length=64)
    """An alarm of the site's ``emergency.alarms`` (its input is what the simulator sets)."""
    raised: bool


def _alerts(request: Request) -> AlertStore:
    return app_service(request, "alerts", AlertStore)


def _feed(request: Request) -> ConsoleFeed:
    return app_service(request, "console", ConsoleFeed)


Alerts = Annotated[AlertStore, Depends(_alerts)]
Feed = Annotated[ConsoleFeed, Depends(_feed)]


@router.get("/alerts")
async def list_alerts(
    _: Watcher, alerts: Alerts, include_acked: bool = False
) -> list[dict[str, Any]]:
    """Open alerts (active, not acknowledged), last seen first (with ``include_acked``: every
    kept one, acknowledged and resolved ones too)."""
    return alerts.listing(include_acked=include_acked)


@router.post("/alerts/ack-all")
async def acknowledge_all_alerts(who: Staff, alerts: Alerts) -> dict[str, Any]:
    """Acknowledge every open alert at once; returns those acknowledged now."""
    done = alerts.acknowledge_all(who.name)
    return {"acknowledged": len(done), "alerts": [a.as_dict() for a in done]}


@router.post("/alerts/{alert_id}/ack")
async def acknowledge_alert(who: Staff, alerts: Alerts, alert_id: Name) -> dict[str, Any]:
    """Acknowledge an alert: who and when are recorded (idempotent). It stays acknowledged
    while its cause persists; an event alert (a failed task) is resolved by it."""
    try:
        return alerts.acknowledge(alert_id, who.name).as_dict()
    except AlertNotFound:
        raise not_found(f"alert {alert_id!r}") from None


@router.post("/robots/{name}/service")
async def set_service(
    who: Staff, manager: Tasks, name: Name, body: Annotated[Service, Body()]
) -> dict[str, Any]:
    """Take a robot out of service (its task goes to another robot; it gets no more tasks
    but go_to and charge pinned to it) or put it back."""
    try:
        robot = manager.set_out_of_service(name, body.out_of_service, by=who.name)
    except TaskNotFound:
        raise not_found(f"robot {name!r}") from None
    return robot.as_dict()


def _library(request: Request) -> Any:
    return request.app.state.rgm.library


@router.get("/nets")
async def list_nets(request: Request, _: NetReader) -> list[str]:
    return list(_library(request).names())


@router.get("/nets/{net}/structure")
async def net_structure(request: Request, _: NetReader, net: Name) -> dict[str, Any]:
    """Places, transitions and arcs of a library net with positions: the PNML drawing where
    the file has one (``layout`` "pnml"), a layered one otherwise ("layered")."""
    try:
        doc = _library(request).get(net).doc
    except UnknownNet:
        raise not_found(f"net {net!r}") from None
    drawing = doc_drawing(doc)

    def node(item: Any, **extra: Any) -> dict[str, Any]:
        x, y = drawing.positions[item.id]
        return {"id": item.id, "name": item.name or item.id, "x": x, "y": y, **extra}

    return {
        "net": net,
        "description": doc.description,
        "layout": drawing.source,
        "places": [node(p, initial=p.initial, final=p.final) for p in doc.places],
        "transitions": [node(t) for t in doc.transitions],
        "arcs": [{"source": a.source, "target": a.target, "weight": a.weight} for a in doc.arcs],
    }


@router.get("/nets/running")
async def running_nets(
    _: NetReader, feed: Feed, target: Annotated[str, Query(min_length=1, max_length=64)]
) -> list[dict[str, Any]]:
    """The nets running on a robot (or on the server, target "rgm") with their marking."""
    return feed.running_nets(target)


@router.post("/nets/kill")
async def kill_net(
    request: Request, who: NetKiller, feed: Feed, body: Annotated[Kill, Body()]
) -> dict[str, Any]:
    """Admin only (the hub's ``kill_petri_net`` rule): stop one running net instance on a
    robot or on the server."""
    known = {n["instance_id"] for n in feed.running_nets(body.target)}
    if body.instance_id not in known:
        raise not_found(f"net instance {body.instance_id!r} on {body.target!r}")
    if body.target == "rgm":
        killed = request.app.state.rgm.kill(body.instance_id)
        return {"target": "rgm", "instance_id": body.instance_id, "killed": bool(killed)}
    feed.endpoint.publish(
        "kill_petri_net", {"instance_id": body.instance_id}, destination=body.target
    )
    return {"target": body.target, "instance_id": body.instance_id, "killed": True, "by": who.name}


@router.get("/building/simulator")
async def simulator_config(request: Request, _: Watcher) -> dict[str, bool]:
    """Whether a building simulator is configured (the console then offers its buttons)."""
    return {"configured": bool(request.app.state.settings.building_sim_url)}


@router.post(
    "/building/simulator/press",
    responses={502: error_response("the building simulator did not answer, or failed")},
)
async def press_simulated(
    request: Request, _: Staff, body: Annotated[Press, Body()]
) -> dict[str, Any]:
    """Press a building button on the building simulator (a demo or test installation)."""
    await _simulator_post(
        request, f"/buttons/{body.button}/press", {"ms": body.ms}, f"button {body.button!r}"
    )
    return {"button": body.button, "ms": body.ms}


@router.post(
    "/building/simulator/alarm",
    responses={502: error_response("the building simulator did not answer, or failed")},
)
async def simulated_alarm(
    request: Request, who: Staff, sites: Sites, body: Annotated[SimulatedAlarm, Body()]
) -> dict[str, Any]:
    """Raise or clear a fire alarm input on the building simulator (a demo or test
    installation): the input reads the alarm's ``active_when`` value, or the other one. The
    server hears it as it hears a real relay (docs/emergency.md)."""
    emergency = sites.site.emergency
    alarms = {a.id: a for a in (emergency.alarms if emergency else [])}
    alarm = alarms.get(body.alarm)
    if alarm is None:
        raise not_found(
            f"alarm {body.alarm!r} (the site's alarms: {', '.join(sorted(alarms)) or 'none'})"
        )
    value = alarm.active_when if body.raised else 1 - alarm.active_when
    where = f"{alarm.input.module}/{alarm.input.point}"
    await _simulator_post(request, f"/points/{where}", {"value": value}, f"point {where}")
    log.warning(
        "%s %s the simulated alarm input %s",
        who.name,
        "raised" if body.raised else "cleared",
        where,
    )
    return {
        "alarm": alarm.id,
        "raised": body.raised,
        "module": alarm.input.module,
        "point": alarm.input.point,
        "value": value,
    }


async def _simulator_post(request: Request, path: str, body: dict[str, Any], what: str) -> None:
    """POST to the building simulator's control API; 409 without one, 404 for ``what`` it
    does not know, 502 when it fails."""
    url = request.app.state.settings.building_sim_url
    if not url:
        raise HTTPException(status.HTTP_409_CONFLICT, "no building simulator is configured")
    try:
        async with httpx.AsyncClient(timeout=5.0) as http:
            reply = await http.post(f"{url.rstrip('/')}{path}", json=body)
    except httpx.HTTPError as exc:
        raise HTTPException(status.HTTP_502_BAD_GATEWAY, f"building simulator: {exc}") from None
    if reply.status_code == 404:
        raise not_found(what)
    if reply.status_code >= 400:
        raise HTTPException(status.HTTP_502_BAD_GATEWAY, f"building simulator: {reply.text}")
