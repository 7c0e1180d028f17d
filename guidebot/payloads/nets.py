"""Payload models of the net library's messages: nets published from the RoboGraph editor
reaching the robots (docs/nets.md, "Publish")."""

from __future__ import annotations

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload

__all__ = ["NetsChanged", "NetsLoaded"]


@register_payload("nets_changed")
class NetsChanged(PayloadModel):
    """The published nets (server -> robots): every net published from the editor, its live
    version's PNML text; a robot starts new instances on them, running ones finish on theirs."""

    version: int
    """The library's publication count: grows with every publish and restore."""
    published_by: str = ""
    nets: dict[str, str] = Field(default_factory=dict)
    """Net name -> its live PNML text (nets never published are the robot's own)."""


@register_payload("nets_loaded")
class NetsLoaded(PayloadModel):
    """A robot now starts nets from this library version (also sent on connect: 0 = none)."""

    robot: str = ""
    version: int
    problems: list[str] = Field(default_factory=list)
    """Why the robot refused the version (empty: installed)."""
