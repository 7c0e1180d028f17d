"""A net as the editor's JSON document, and back: what the RoboGraph editor (/nets/) edits.

The JSON is the model of ``petri_nets.model`` without file details (lines, foreign elements):
every place and transition has a position, so a net written from it (``write_pnml``) carries its
drawing. ``check_net`` validates it with the engine's own rules (``petri_nets.validate``, what
``guidebot petri check`` runs) and names the element each problem concerns: each element gets
a line of its own when the document is built, and a problem's line leads back to it.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from petri_nets.layout import doc_drawing
from petri_nets.model import (
    REQUIRED,
    ActionSpec,
    ArcSpec,
    ConditionSpec,
    MatchSpec,
    NetDoc,
    PageSpec,
    ParamSpec,
    PlaceSpec,
    TransitionSpec,
)
from petri_nets.pnml import read_pnml
from petri_nets.pnml_writer import write_pnml
from petri_nets.validate import validate
from petri_nets.xmlsafe import Node

__all__ = [
    "EditorNet",
    "check_net",
    "doc_to_editor",
    "editor_to_doc",
    "editor_to_pnml",
    "pnml_to_editor",
]

Point = Annotated[list[float], Field(min_length=2, max_length=2)]
"""[x, y] (a JSON array: strict models take no tuple from JSON)."""
Id = Field(min_length=1, max_length=100, pattern=r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
Text = Field(default=None, max_length=10_000)


class _Strict(BaseModel):
    """Unknown keys refused, no coercion (``true`` is not 1, ``"2"`` not 2), as every request
    body of the API (tests/server/test_contract.py)."""

    model_config = ConfigDict(extra="forbid", strict=True)


class EditorParam(_Strict):
    name: str = Id
    required: bool = False
    default: Any = None


class EditorAction(_Strict):
    kind: str = Field(min_length=1, max_length=40)
    type: str | None = Text
    destination: str | None = Text
    body: str = Field(default="", max_length=100_000)
    net: str | None = Text
    seconds: str | None = Text
    list: str | None = Text
    var: str | None = Text
    order: str | None = Text


class EditorMatch(_Strict):
    field: str = Field(min_length=1, max_length=200)
    value: str = Field(max_length=10_000)


class EditorBind(_Strict):
    var: str = Field(min_length=1, max_length=200)
    field: str = Field(min_length=1, max_length=200)


class EditorCondition(_Strict):
    kind: str = Field(min_length=1, max_length=40)
    type: str | None = Text
    matches: list[EditorMatch] = Field(default_factory=list, max_length=100)
    binds: list[EditorBind] = Field(default_factory=list, max_length=100)
    net: str | None = Text
    outcome: str | None = Text
    var: str | None = Text
    test: str | None = Text
    value: str | None = Text


class EditorPlace(_Strict):
    id: str = Id
    name: str | None = Field(default=None, max_length=200)
    x: float = 0.0
    y: float = 0.0
    initial: int = Field(default=0, ge=0, le=1_000_000)
    final: bool = False
    outcome: Literal["done", "failed"] = "done"
    action: EditorAction | None = None


class EditorTransition(_Strict):
    id: str = Id
    name: str | None = Field(default=None, max_length=200)
    x: float = 0.0
    y: float = 0.0
    priority: int = Field(default=0, ge=-1_000_000, le=1_000_000)
    condition: EditorCondition | None = None


class EditorArc(_Strict):
    id: str = Id
    source: str = Field(min_length=1, max_length=100)
    target: str = Field(min_length=1, max_length=100)
    weight: int = Field(default=1, ge=1, le=1_000_000)
    points: list[Point] = Field(default_factory=list, max_length=100)
    """Bend points from source to target (PNML arc graphics positions)."""


class EditorNet(_Strict):
    """One net as the editor holds it."""

    id: str = Id
    name: str | None = Field(default=None, max_length=200)
    description: str = Field(default="", max_length=100_000)
    endless: bool = False
    task: bool = True
    layout: str | None = None
    """Where the positions came from when the net was opened ("pnml", "layered"): ignored."""
    params: list[EditorParam] = Field(default_factory=list, max_length=1000)
    places: list[EditorPlace] = Field(default_factory=list, max_length=5000)
    transitions: list[EditorTransition] = Field(default_factory=list, max_length=5000)
    arcs: list[EditorArc] = Field(default_factory=list, max_length=20000)


def _graphics(x: float, y: float) -> Node:
    position = Node("position", {"x": str(round(x)), "y": str(round(y))}, 0)
    return Node("graphics", {}, 0, [position])


def _bends(graphics: Node | None) -> list[list[float]]:
    """An arc's bend points: its graphics positions, in order (unreadable ones skipped)."""
    out = []
    for position in graphics.findall("position") if graphics is not None else []:
        try:
            out.append([float(position.attrib["x"]), float(position.attrib["y"])])
        except (KeyError, ValueError):
            continue
    return out


def _arc_graphics(points: list[list[float]]) -> Node | None:
    if not points:
        return None
    positions = [Node("position", {"x": str(round(x)), "y": str(round(y))}, 0) for x, y in points]
    return Node("graphics", {}, 0, positions)


def _drop_none(data: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in data.items() if v is not None}


def doc_to_editor(doc: NetDoc) -> dict[str, Any]:
    """The editor's document of a net read from a file: its drawing, else a layered one."""
    drawing = doc_drawing(doc)
    at = drawing.positions

    def action(a: ActionSpec | None) -> dict[str, Any] | None:
        if a is None:
            return None
        keys = ("kind", "type", "destination", "net", "seconds", "list", "var", "order")
        return _drop_none({k: getattr(a, k) for k in keys}) | {"body": a.body}

    def condition(c: ConditionSpec | None) -> dict[str, Any] | None:
        if c is None:
            return None
        keys = ("kind", "type", "net", "outcome", "var", "test", "value")
        return _drop_none({k: getattr(c, k) for k in keys}) | {
            "matches": [{"field": m.field, "value": m.value} for m in c.matches],
            "binds": [{"var": v, "field": f} for v, f in c.binds],
        }

    return {
        "id": doc.id,
        "name": doc.name,
        "description": doc.description,
        "endless": doc.endless,
        "task": doc.task,
        "layout": drawing.source,
        "params": [
            {"name": p.name, "required": True}
            if p.default is REQUIRED
            else {"name": p.name, "required": False, "default": p.default}
            for p in doc.params
        ],
        "places": [
            {
                "id": p.id,
                "name": p.name,
                "x": at[p.id][0],
                "y": at[p.id][1],
                "initial": p.initial,
                "final": p.final,
                "outcome": p.outcome,
                "action": action(p.action),
            }
            for p in doc.places
        ],
        "transitions": [
            {
                "id": t.id,
                "name": t.name,
                "x": at[t.id][0],
                "y": at[t.id][1],
                "priority": t.priority,
                "condition": condition(t.condition),
            }
            for t in doc.transitions
        ],
        "arcs": [
            {
                "id": a.id,
                "source": a.source,
                "target": a.target,
                "weight": a.weight,
                # bends only with the file's own drawing: a layered one moved the nodes
                "points": _bends(a.graphics) if drawing.source == "pnml" else [],
            }
            for a in doc.arcs
        ],
    }


def editor_to_doc(net: EditorNet) -> tuple[NetDoc, dict[int, str]]:
    """The model of the editor's net, and which element each line stands for ("net",
    "param:NAME", "place:ID", "transition:ID", "arc:ID"): lines are given one per element."""
    where: dict[int, str] = {1: "net"}

    def line(key: str) -> int:
        number = len(where) + 1
        where[number] = key
        return number

    doc = NetDoc(
        id=net.id,
        file=f"{net.id}.pnml",
        line=1,
        name=net.name or net.id,
        description=net.description,
        endless=net.endless,
        task=net.task,
        pages=[PageSpec("page1", None, 1)],
    )
    for param in net.params:
        default = REQUIRED if param.required else param.default
        doc.params.append(ParamSpec(param.name, default, line(f"param:{param.name}")))
    for place in net.places:
        n = line(f"place:{place.id}")
        act = place.action
        doc.places.append(
            PlaceSpec(
                place.id,
                n,
                "page1",
                name=place.name or None,
                initial=place.initial,
                final=place.final,
                outcome=place.outcome,
                graphics=_graphics(place.x, place.y),
                action=None
                if act is None
                else ActionSpec(
                    act.kind,
                    n,
                    type=act.type or None,
                    destination=act.destination or None,
                    body=act.body,
                    net=act.net or None,
                    seconds=act.seconds or None,
                    list=act.list or None,
                    var=act.var or None,
                    order=act.order or None,
                ),
            )
        )
    for trans in net.transitions:
        n = line(f"transition:{trans.id}")
        cond = trans.condition
        doc.transitions.append(
            TransitionSpec(
                trans.id,
                n,
                "page1",
                name=trans.name or None,
                priority=trans.priority,
                graphics=_graphics(trans.x, trans.y),
                condition=None
                if cond is None
                else ConditionSpec(
                    cond.kind,
                    n,
                    type=cond.type or None,
                    matches=[MatchSpec(m.field, m.value, n) for m in cond.matches],
                    binds=[(b.var, b.field) for b in cond.binds],
                    net=cond.net or None,
                    outcome=cond.outcome or None,
                    var=cond.var or None,
                    test=cond.test or None,
                    value=cond.value,
                ),
            )
        )
    for arc in net.arcs:
        doc.arcs.append(
            ArcSpec(
                arc.id,
                arc.source,
                arc.target,
                line(f"arc:{arc.id}"),
                "page1",
                arc.weight,
                graphics=_arc_graphics(arc.points),
            )
        )
    return doc, where


def check_net(net: EditorNet) -> list[dict[str, str]]:
    """The engine's problems with the net, each as ``{"element": key, "message": text}``."""
    doc, where = editor_to_doc(net)
    problems = validate(doc)
    return [{"element": where.get(p.line, "net"), "message": p.message} for p in problems]


def editor_to_pnml(net: EditorNet) -> bytes:
    """The net as a PNML file with its drawing (positions on every place and transition)."""
    doc, _ = editor_to_doc(net)
    return write_pnml(doc)


def pnml_to_editor(
    data: bytes | str, file: str = "upload.pnml"
) -> tuple[dict[str, Any] | None, list[str]]:
    """A PNML file read for the editor: (its document, []) or (None, the reader's problems)."""
    doc, problems = read_pnml(data, file)
    if doc is None:
        return None, [str(p) for p in problems]
    return doc_to_editor(doc), [str(p) for p in problems]
