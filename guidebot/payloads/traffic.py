"""Payload models of the traffic messages (registered by type name)."""

from __future__ import annotations

from typing import Any

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload
from guidebot.site.steps import PathStep

__all__ = [
    "AreaGranted",
    "AreaYield",
    "ClosuresChanged",
    "GetPath",
    "Path",
    "PathStep",
    "ReleaseArea",
    "RequestArea",
]


@register_payload("get_path")
class GetPath(PayloadModel):
    robot: str = ""
    from_node: str | None = None
    """None: from the robot's current node (last robot_state)."""
    to_node: str
    step_free: bool = False
    """A step-free tour's leg: no edge with steps (``Edge.steps``); the answer is ``closed``
    with the reason ``steps`` when only such edges lead there."""


@register_payload("path")
class Path(PayloadModel):
    nodes: list[str] = Field(default_factory=list)
    length_m: float | None = None
    steps: list[PathStep] = Field(default_factory=list)
    error: str | None = None
    """Set (and nodes empty) when there is no path or a node is unknown."""
    closed: bool = False
    """With ``error``: only closed elements lead there (building modes or trouble)."""
    reason: str | None = None
    """With ``closed``: the closures' reasons ("gallery g2 closed: cleaning"), for the visitor."""
    trouble: bool = False
    """With ``closed``: every closure that cuts the way off is trouble (a jammed door, a stuck
    lift: it lifts itself), none is by staff; a robot told to wait for trouble
    (``navigate_to``'s ``trouble_wait_s``) waits for this one, and reads no ``reason`` text."""


@register_payload("request_area")
class RequestArea(PayloadModel):
    robot: str
    area: str


@register_payload("area_granted")
class AreaGranted(PayloadModel):
    robot: str
    area: str
    removed: bool = False
    """The area is no longer on the site (a publish removed it): nothing to hold, go on."""
    reason: str = ""
    """Why, for the robot's log (set with ``removed``)."""


@register_payload("release_area")
class ReleaseArea(PayloadModel):
    robot: str
    area: str


@register_payload("area_yield")
class AreaYield(PayloadModel):
    """Deadlock resolution: leave ``area`` for ``go_to_node``, release it, then ask again."""

    robot: str
    area: str
    go_to_node: str


@register_payload("closures_changed")
class ClosuresChanged(PayloadModel):
    """Building modes and trouble (backend/closures): the nodes closed to robots now. A robot
    whose path ahead crosses one plans again; while any is closed it plans with the server."""

    nodes: list[str] = Field(default_factory=list)
    closures: list[dict[str, Any]] = Field(default_factory=list)
    """Each closure as ``GET /api/closures`` shows it (consoles draw them on the map)."""
