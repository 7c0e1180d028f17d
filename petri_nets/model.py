"""The document model of a net: what a PNML file says, before it is compiled for running.

Kept close to the file (ids, names, pages, graphics, other tools' data) so a net can be written
back; ``petri_nets.compiled`` turns it into index-based tables for the engine.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from petri_nets.xmlsafe import Node

__all__ = [
    "ACTION_KINDS",
    "CONDITION_KINDS",
    "OUTCOMES",
    "REQUIRED",
    "ActionSpec",
    "ArcSpec",
    "ConditionSpec",
    "MatchSpec",
    "NetDoc",
    "PageSpec",
    "ParamSpec",
    "PlaceSpec",
    "Problem",
    "TransitionSpec",
]

ACTION_KINDS = ("publish", "timer", "run", "kill", "next")
CONDITION_KINDS = ("message", "timer", "net_ended", "guard")
OUTCOMES = ("done", "failed")
GUARD_TESTS = ("set", "unset", "equals")


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()
"""The default of a parameter that has none: the caller must give it."""


@dataclass(frozen=True, order=True)
class Problem:
    """One validation error, printed as ``file:line: message``."""

    file: str
    line: int
    message: str

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.message}"


@dataclass
class ActionSpec:
    kind: str
    line: int
    type: str | None = None
    destination: str | None = None
    body: str = ""
    net: str | None = None
    seconds: str | None = None
    list: str | None = None
    var: str | None = None
    order: str | None = None


@dataclass
class MatchSpec:
    field: str
    value: str
    line: int


@dataclass
class ConditionSpec:
    kind: str
    line: int
    type: str | None = None
    matches: list[MatchSpec] = field(default_factory=list)
    binds: list[tuple[str, str]] = field(default_factory=list)
    net: str | None = None
    outcome: str | None = None
    var: str | None = None
    test: str | None = None
    value: str | None = None


@dataclass
class ParamSpec:
    name: str
    default: Any
    line: int


@dataclass
class PlaceSpec:
    id: str
    line: int
    page: str
    name: str | None = None
    initial: int = 0
    action: ActionSpec | None = None
    final: bool = False
    outcome: str = "done"
    graphics: Node | None = None
    name_graphics: Node | None = None
    foreign: list[Node] = field(default_factory=list)


@dataclass
class TransitionSpec:
    id: str
    line: int
    page: str
    name: str | None = None
    condition: ConditionSpec | None = None
    priority: int = 0
    graphics: Node | None = None
    name_graphics: Node | None = None
    foreign: list[Node] = field(default_factory=list)


@dataclass
class ArcSpec:
    id: str
    source: str
    target: str
    line: int
    page: str
    weight: int = 1
    graphics: Node | None = None
    foreign: list[Node] = field(default_factory=list)


@dataclass
class PageSpec:
    id: str
    parent: str | None
    line: int
    graphics: Node | None = None


@dataclass
class NetDoc:
    """One net as read from a file."""

    id: str
    file: str
    line: int
    type: str = ""
    name: str | None = None
    description: str = ""
    params: list[ParamSpec] = field(default_factory=list)
    endless: bool = False
    places: list[PlaceSpec] = field(default_factory=list)
    transitions: list[TransitionSpec] = field(default_factory=list)
    arcs: list[ArcSpec] = field(default_factory=list)
    pages: list[PageSpec] = field(default_factory=list)
    foreign: list[Node] = field(default_factory=list)

    @property
    def label(self) -> str:
        """The name the library knows the net by."""
        return self.id
