"""A closure: one element of the site closed to robots, now or between two times.

Kinds: ``area`` (a gallery: a restricted area's nodes), ``nodes`` (a set of nodes out of
service), ``door`` (its node), ``elevator`` (its stops: no ride). Staff closures are kept in the
database (``source`` "staff"); trouble (a door that did not open, a lift that did not come) is
kept in memory only (``source`` "trouble") and lifts itself."""

from __future__ import annotations

import time
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from guidebot.site.schema import Site

__all__ = ["Closure", "ClosureError", "ClosureKind", "ClosureRequest", "closed_nodes"]

ClosureKind = Literal["area", "nodes", "door", "elevator"]


class ClosureError(ValueError):
    """A closure the site cannot have (an unknown area, door, elevator or node)."""


class ClosureRequest(BaseModel):
    """What staff ask for (REST body): which element, why, and when (none: from now on).
    Strict as every REST body (backend.rest.models.RequestBody, not imported: this module sits
    below the Traffic Manager, which the REST kit's typed services name)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    kind: ClosureKind
    target: str = Field(default="", max_length=64)
    """The area, door or elevator id (kind ``nodes``: empty)."""
    nodes: list[str] = Field(default_factory=list, max_length=10_000)
    """Kind ``nodes``: the nodes out of service."""
    reason: str = Field(min_length=1, max_length=300)
    """Said to staff, and to the visitor whose tour skips a stop for it."""
    start: float | None = Field(default=None, ge=0)
    """Unix seconds it begins (None: now)."""
    end: float | None = Field(default=None, ge=0)
    """Unix seconds it ends by itself (None: until staff reopen it)."""

    @model_validator(mode="after")
    def _consistent(self) -> ClosureRequest:
        if self.kind == "nodes":
            if not self.nodes:
                raise ValueError("a closure of kind nodes needs at least one node")
            if self.target:
                raise ValueError("a closure of kind nodes names nodes, not a target")
        elif not self.target:
            raise ValueError(f"a closure of kind {self.kind} needs a target ({self.kind} id)")
        elif self.nodes:
            raise ValueError(f"a closure of kind {self.kind} names a target, not nodes")
        if self.start is not None and self.end is not None and self.end <= self.start:
            raise ValueError("end must come after start")
        return self


class Closure(BaseModel):
    """A closure as kept and shown (``GET /api/closures``)."""

    id: str
    kind: ClosureKind
    target: str = ""
    nodes: list[str] = Field(default_factory=list)
    reason: str
    start: float | None = None
    end: float | None = None
    by: str = ""
    """Who closed it (a token's name), or ``trouble``."""
    source: Literal["staff", "trouble"] = "staff"
    created_at: float = Field(default_factory=time.time)

    def active(self, now: float) -> bool:
        """In force at ``now`` (Unix seconds)."""
        return (self.start is None or self.start <= now) and (self.end is None or now < self.end)

    def over(self, now: float) -> bool:
        return self.end is not None and now >= self.end

    def what(self) -> str:
        """The element in words: "gallery g2", "door d1", "nodes n1, n2"."""
        if self.kind == "nodes":
            shown = ", ".join(self.nodes[:5]) + (" ..." if len(self.nodes) > 5 else "")
            return f"nodes {shown}"
        word = {"area": "gallery", "door": "door", "elevator": "elevator"}[self.kind]
        return f"{word} {self.target}"

    def view(self, now: float) -> dict[str, Any]:
        data = self.model_dump()
        data["active"] = self.active(now)
        data["what"] = self.what()
        return data


def element_nodes(site: Site, kind: str, target: str, nodes: list[str]) -> list[str]:
    """The map nodes a closure takes out; ClosureError naming what the site lacks."""
    if kind == "nodes":
        known = {n.id for n in site.nodes}
        missing = [n for n in nodes if n not in known]
        if missing:
            raise ClosureError(f"unknown node(s): {', '.join(missing[:10])}")
        return list(dict.fromkeys(nodes))
    if kind == "area":
        area = next((a for a in site.areas if a.id == target), None)
        if area is None:
            raise ClosureError(f"unknown area {target!r} (the site's areas: {_ids(site.areas)})")
        return list(area.nodes)
    if kind == "door":
        door = next((d for d in site.doors if d.id == target), None)
        if door is None:
            raise ClosureError(f"unknown door {target!r} (the site's doors: {_ids(site.doors)})")
        return [door.node]
    elevator = next((e for e in site.elevators if e.id == target), None)
    if elevator is None:
        raise ClosureError(
            f"unknown elevator {target!r} (the site's elevators: {_ids(site.elevators)})"
        )
    return [s.node for s in elevator.stops]


def _ids(items: list[Any]) -> str:
    return ", ".join(i.id for i in items) or "none"


def closed_nodes(site: Site, closures: list[Closure], now: float) -> dict[str, Closure]:
    """Node -> the closure that takes it out (the first in force), at ``now``. A closure whose
    element the site no longer has closes nothing."""
    out: dict[str, Closure] = {}
    for closure in closures:
        if not closure.active(now):
            continue
        try:
            nodes = element_nodes(site, closure.kind, closure.target, closure.nodes)
        except ClosureError:
            continue
        for node in nodes:
            out.setdefault(node, closure)
    return out
