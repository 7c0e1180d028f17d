"""Payloads of the fire alarm (docs/emergency.md, docs/messages.md "Emergency")."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload

__all__ = [
    "EmergencyChanged",
    "Evacuate",
    "EvacuationState",
    "EvacuationStateName",
    "LandingWay",
]

EvacuationStateName = Literal["stopped", "moving", "safe", "stuck"]


@register_payload("emergency_changed")
class EmergencyChanged(PayloadModel):
    """The server's emergency state, broadcast on every change (and to a client on connect)."""

    state: Literal["normal", "alarm", "input_clear"]
    zones: list[dict[str, list[str]]] = Field(default_factory=list)
    """Each held zone as in the site: ``{}`` the whole site, ``{"floors": [..]}`` or
    ``{"areas": [..]}``."""
    since: float | None = None
    declared_by: str = ""
    reason: str = ""
    words: dict[str, str] = Field(default_factory=dict)


class LandingWay(PayloadModel):
    """The way to safety from one landing of an elevator (the cabin's node on that floor)."""

    safe_spot: str | None
    path: list[str] = Field(default_factory=list)
    steps: list[dict[str, Any]] = Field(default_factory=list)


@register_payload("evacuate")
class Evacuate(PayloadModel):
    """Server -> one robot of an alarm's zone: stop now, then drive ``path`` to ``safe_spot``."""

    safe_spot: str | None
    path: list[str] = Field(default_factory=list)
    """Nodes from where the server last saw the robot to the safe spot, no elevator, no escape
    route entered; empty: no way (the robot stops and reports ``stuck``)."""
    steps: list[dict[str, Any]] = Field(default_factory=list)
    """The path as ``path`` message steps (node, floor, x, y, area; never a door or an
    elevator: the robot asks for neither on this way)."""
    words: dict[str, str] = Field(default_factory=dict)
    """What to say, per language; the site's default language first."""
    landings: dict[str, dict[str, LandingWay]] = Field(default_factory=dict)
    """Elevator -> floor -> the way from that landing, for each elevator the robot may be
    riding (it was last seen on one of its cabin's nodes or next to one). A robot riding a
    cabin when the order comes stays in it and gets out at the landing where it next stands
    with its door open, then takes that landing's way."""


@register_payload("evacuation_state")
class EvacuationState(PayloadModel):
    """Robot -> server: where its evacuation stands."""

    state: EvacuationStateName
    node: str | None = None
    why: str = ""
    stopped_at: float | None = None
    """``stopped`` only: when (Unix seconds) the zero-velocity command reached the base, i.e.
    its frame went out on the robot's CAN bus (the base sends it inline); None: not seen."""
