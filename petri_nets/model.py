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
    "FinalMarking",
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
    element: Node | None = None


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
    element: Node | None = None


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
    element: Node | None = None
    written: tuple[str, str] | None = None
    """Source and target as the file wrote them, when one is a reference node."""


@dataclass
class PageSpec:
    id: str
    parent: str | None
    line: int
    graphics: Node | None = None
    element: Node | None = None
    implicit: bool = False
    """Nodes written directly under ``<net>`` (older PNML, WoPeD, PIPE): no ``<page>`` element."""


@dataclass
class FinalMarking:
    """A final marking another tool declared (ProM's ``<finalmarkings>``); unlisted places 0."""

    counts: dict[str, int]
    line: int
    lines: dict[str, int] = field(default_factory=dict)
    """Line of each place's entry."""


@dataclass
class NetDoc:
    """One net as read from a file.

    ``task`` tells the two dialects apart: a GuideBot task net has at least one
    ``<toolspecific tool="guidebot">`` element (nets built in Python are task nets); a plain net
    (any other tool's PNML) runs as a bare place/transition net (docs/petri-nets.md).
    """

    id: str
    file: str
    line: int
    type: str = ""
    task: bool = True
    name: str | None = None
    description: str = ""
    params: list[ParamSpec] = field(default_factory=list)
    endless: bool = False
    places: list[PlaceSpec] = field(default_factory=list)
    transitions: list[TransitionSpec] = field(default_factory=list)
    arcs: list[ArcSpec] = field(default_factory=list)
    pages: list[PageSpec] = field(default_factory=list)
    foreign: list[Node] = field(default_factory=list)
    final_markings: list[FinalMarking] = field(default_factory=list)
    element: Node | None = None
    """The ``<net>`` element read; with ``root`` (``<pnml>``) it is how a file is written back
    as it came: unknown elements, other tools' data and the namespace kept."""
    root: Node | None = None

    @property
    def label(self) -> str:
        """The name the library knows the net by."""
        return self.id
