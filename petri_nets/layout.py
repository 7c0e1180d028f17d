"""A layered drawing of a net: where the builder puts the library's places and transitions, and
what the console's monitor draws for a PNML file without graphics.

Sugiyama in small: back arcs (loops) are set aside, every node goes one layer below its
deepest predecessor (top to bottom, the way a net runs), nodes within a layer are ordered by
the mean column of their neighbours (fewer crossings), and each column is as wide as its
widest label, so labels written to the right of their node never overlap.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from petri_nets.model import NetDoc
    from petri_nets.xmlsafe import Node

__all__ = [
    "LABEL_CHAR_PX",
    "LAYER_PX",
    "Drawing",
    "doc_drawing",
    "graphics_position",
    "layered",
    "net_drawing",
]

LAYER_PX = 60.0
"""Vertical distance between two layers."""
LABEL_CHAR_PX = 7.0
"""Width of one label character at the monitor's 12 px font (generous: labels never touch)."""
NODE_PX = 40.0
"""A node with its margin, before its label."""
MARGIN_PX = 40.0
SWEEPS = 4


@dataclass(frozen=True)
class Drawing:
    """Positions by node id, and where they came from ("pnml" or "layered")."""

    positions: dict[str, tuple[float, float]]
    source: str


def layered(
    nodes: Sequence[tuple[str, str]],
    arcs: Sequence[tuple[str, str]],
    starts: Sequence[str] = (),
) -> dict[str, tuple[float, float]]:
    """Positions for ``nodes`` ((id, label) in file order) joined by ``arcs`` ((source,
    target)); layering begins at ``starts`` (the initially marked places), else at the nodes
    nothing leads to, else at the first node."""
    ids = [n for n, _ in nodes]
    label = dict(nodes)
    succ: dict[str, list[str]] = {n: [] for n in ids}
    pred_count = dict.fromkeys(ids, 0)
    for s, t in arcs:
        if s in succ and t in succ and t not in succ[s]:
            succ[s].append(t)
            pred_count[t] += 1
    roots = [n for n in starts if n in succ] or [n for n in ids if not pred_count[n]] or ids[:1]
    forward = _forward_arcs(ids, succ, roots)
    layer = _layers(ids, forward)
    rows: dict[int, list[str]] = {}
    for n in ids:  # file order within a layer to begin with
        rows.setdefault(layer[n], []).append(n)
    neighbours: dict[str, list[str]] = {n: [] for n in ids}
    for s, t in forward:
        neighbours[s].append(t)
        neighbours[t].append(s)
    _order(rows, neighbours)
    column = {n: i for row in rows.values() for i, n in enumerate(row)}
    width = [0.0] * (max(column.values(), default=-1) + 1)
    for n in ids:
        width[column[n]] = max(width[column[n]], NODE_PX + LABEL_CHAR_PX * len(label[n]))
    left = [MARGIN_PX + sum(width[:c]) for c in range(len(width))]
    return {n: (left[column[n]], MARGIN_PX + LAYER_PX * layer[n]) for n in ids}


def _forward_arcs(
    ids: list[str], succ: dict[str, list[str]], roots: list[str]
) -> list[tuple[str, str]]:
    """The arcs of a depth-first walk from the roots, minus those closing a loop."""
    state: dict[str, int] = {}  # 1 on the walk's path, 2 done
    forward: list[tuple[str, str]] = []
    for root in [*roots, *ids]:
        if root in state:
            continue
        stack = [(root, iter(succ[root]))]
        state[root] = 1
        while stack:
            node, children = stack[-1]
            child = next(children, None)
            if child is None:
                state[node] = 2
                stack.pop()
            elif state.get(child) == 1:
                continue  # a back arc: a loop, drawn but not layered
            else:
                forward.append((node, child))
                if child not in state:
                    state[child] = 1
                    stack.append((child, iter(succ[child])))
    return forward


def _layers(ids: list[str], forward: list[tuple[str, str]]) -> dict[str, int]:
    """Longest path from the roots over the loop-free arcs."""
    incoming: dict[str, list[str]] = {n: [] for n in ids}
    for s, t in forward:
        incoming[t].append(s)
    layer: dict[str, int] = {}

    def depth(node: str) -> int:
        todo = [node]
        while todo:
            n = todo[-1]
            if n in layer:
                todo.pop()
                continue
            missing = [p for p in incoming[n] if p not in layer]
            if missing:
                todo.extend(missing)
            else:
                layer[n] = 1 + max((layer[p] for p in incoming[n]), default=-1)
                todo.pop()
        return layer[node]

    for n in ids:
        depth(n)
    return layer


def _order(rows: dict[int, list[str]], neighbours: dict[str, list[str]]) -> None:
    """Barycentre sweeps, down then up: each node moves toward its neighbours' columns."""
    keys = sorted(rows)
    for sweep in range(SWEEPS):
        for key in keys if sweep % 2 == 0 else reversed(keys):
            position = {n: i for row in rows.values() for i, n in enumerate(row)}
            rows[key] = sorted(rows[key], key=lambda n: _centre(n, position, neighbours))


def _centre(
    node: str, position: dict[str, int], neighbours: dict[str, list[str]]
) -> tuple[float, int]:
    """The mean column of a node's neighbours (all in other layers; its own if none)."""
    near = [position[m] for m in neighbours[node]]
    return (sum(near) / len(near) if near else float(position[node]), position[node])


def net_drawing(
    places: Sequence[tuple[str, str, tuple[float, float] | None, int]],
    transitions: Sequence[tuple[str, str, tuple[float, float] | None]],
    arcs: Sequence[tuple[str, str]],
) -> Drawing:
    """The file's own drawing when every place and transition has a position, else a layered
    one (a partial drawing is not one a person can follow). Places are (id, label, position,
    initial tokens), transitions (id, label, position)."""
    own = {p[0]: p[2] for p in places} | {t[0]: t[2] for t in transitions}
    if own and all(xy is not None for xy in own.values()):
        return Drawing({k: v for k, v in own.items() if v is not None}, "pnml")
    nodes = [(p[0], p[1]) for p in places] + [(t[0], t[1]) for t in transitions]
    starts = [p[0] for p in places if p[3] > 0]
    return Drawing(layered(nodes, arcs, starts), "layered")


def graphics_position(graphics: Node | None) -> tuple[float, float] | None:
    """A place's or transition's PNML position; None when it has none or it is unreadable."""
    position = graphics.find("position") if graphics is not None else None
    if position is None:
        return None
    try:
        return float(position.attrib["x"]), float(position.attrib["y"])
    except (KeyError, ValueError):
        return None


def doc_drawing(doc: NetDoc) -> Drawing:
    """``net_drawing`` of a net read from a file (the console's monitor, the net editor)."""
    return net_drawing(
        [(p.id, p.name or p.id, graphics_position(p.graphics), p.initial) for p in doc.places],
        [(t.id, t.name or t.id, graphics_position(t.graphics)) for t in doc.transitions],
        [(a.source, a.target) for a in doc.arcs],
    )
