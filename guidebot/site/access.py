"""Step-free visits (docs/visitor.md, "A step-free tour"): which points a visitor who takes no
steps (``Edge.steps``) cannot reach, and which stops a step-free tour skips, for ``guidebot site
check``, the visitor panel, the touch screen, the Task Manager and its estimates: one rule.

A visitor comes in where the site's step-free part is: the largest set of nodes that reach one
another over no edge with steps (its "heart"). A point no step-free way leads to from there is
reached only by steps: a step-free visit to it is refused, and a step-free tour whose first
stop it is starts at the next stop the visitor can reach (the robot meets them there). From the
first stop on, the robot guiding a step-free tour goes from each stop to the next over
step-free paths only (the Traffic Manager's ``get_path`` with ``step_free``); a stop no such
path leads to from the stop before is skipped, and the tour goes on from where it is.
"""

from __future__ import annotations

from collections.abc import Container, Iterable

from guidebot.site.graph import SiteGraph
from guidebot.site.schema import PointOfInterest, Site, Tour
from guidebot.site.validate import SiteIssue

__all__ = [
    "STEPS_REASON",
    "first_stops_skipped",
    "graph_of",
    "step_free_skips",
    "step_free_warnings",
    "steps_only_nodes",
]

STEPS_REASON = "steps"
"""A skip's reason when only steps lead there (docs/protocol.md, "Skipped stops")."""

_steps_only: dict[int, tuple[SiteGraph, frozenset[str]]] = {}
"""id(graph) -> (graph, its steps-only nodes): one walk per site version."""
_graphs: dict[int, tuple[Site, SiteGraph]] = {}
"""id(site) -> (site, its graph without tables): for callers that hold only the site."""


def graph_of(site: Site) -> SiteGraph:
    """The structure of ``site``'s graph (no path tables: cheap), built once per site."""
    found = _graphs.get(id(site))
    if found is None or found[0] is not site:
        if len(_graphs) > 4:
            _graphs.clear()  # sites replaced by edits
        found = _graphs[id(site)] = (site, SiteGraph(site, warm=False, tables=False))
    return found[1]


def _level(graph: SiteGraph, node: str) -> list[str]:
    return [n for n, _ in graph.adj.get(node, ()) if (node, n) not in graph.step_edges]


def _heart(graph: SiteGraph) -> list[str]:
    """The largest set of nodes that reach one another over no edge with steps (Kosaraju's
    strongly connected components, iterative; the first found wins a tie)."""
    order: list[str] = []
    seen: set[str] = set()
    for root in graph.names:
        if root in seen:
            continue
        seen.add(root)
        stack = [(root, iter(_level(graph, root)))]
        while stack:
            node, nexts = stack[-1]
            for nxt in nexts:
                if nxt not in seen:
                    seen.add(nxt)
                    stack.append((nxt, iter(_level(graph, nxt))))
                    break
            else:
                stack.pop()
                order.append(node)
    back: dict[str, list[str]] = {n: [] for n in graph.names}
    for n in graph.names:
        for m in _level(graph, n):
            back[m].append(n)
    best: list[str] = []
    placed: set[str] = set()
    for root in reversed(order):
        if root in placed:
            continue
        placed.add(root)
        part, todo = [root], [root]
        while todo:
            for prev in back[todo.pop()]:
                if prev not in placed:
                    placed.add(prev)
                    part.append(prev)
                    todo.append(prev)
        if len(part) > len(best):
            best = part
    return best


def _reach(graph: SiteGraph, sources: Iterable[str], level: bool) -> set[str]:
    seen = set(sources)
    todo = list(seen)
    while todo:
        node = todo.pop()
        for nxt, _ in graph.adj.get(node, ()):
            if nxt not in seen and not (level and (node, nxt) in graph.step_edges):
                seen.add(nxt)
                todo.append(nxt)
    return seen


def steps_only_nodes(graph: SiteGraph) -> frozenset[str]:
    """The nodes reached from the site's step-free heart only over steps (the building as
    built: closures are the building modes' business, not the steps')."""
    found = _steps_only.get(id(graph))
    if found is None or found[0] is not graph:
        if len(_steps_only) > 8:
            _steps_only.clear()  # sites replaced by edits
        nodes: frozenset[str] = frozenset()
        if graph.step_edges:
            heart = _heart(graph)
            nodes = frozenset(_reach(graph, heart, False) - _reach(graph, heart, True))
        found = _steps_only[id(graph)] = (graph, nodes)
    return found[1]


def first_stops_skipped(site: Site, graph: SiteGraph, tour: Tour) -> list[PointOfInterest]:
    """The stops at the start of ``tour`` that a step-free visitor cannot reach (only steps
    lead there): a step-free tour starts after them."""
    cut = steps_only_nodes(graph)
    out: list[PointOfInterest] = []
    for poi_id in tour.points:
        poi = site.poi(poi_id)
        if poi is None or poi.node not in graph:
            continue
        if poi.node not in cut:
            break
        out.append(poi)
    return out


def step_free_skips(
    site: Site, graph: SiteGraph, tour: Tour, closed: Container[str] = frozenset()
) -> list[str]:
    """The points of ``tour`` a step-free tour skips (none when the site marks no steps): the
    first stops while only steps lead to them (``first_stops_skipped``), then each stop no
    step-free way leads to from the stop before. ``closed``: the nodes closed now (building
    modes): a later stop whose step-free ways all cross them is skipped too; a stop closures
    cut off for every tour (only closed nodes lead there) is not the steps' doing and is not
    listed, and the tour goes on from the stop before, as it will."""
    if not graph.step_edges:
        return []
    skipped = [p.id for p in first_stops_skipped(site, graph, tour)]
    here: str | None = None
    for poi_id in tour.points[len(skipped) :]:
        poi = site.poi(poi_id)
        if poi is None or poi.node not in graph:
            continue
        if (
            here is not None
            and here != poi.node
            and graph.step_free_path(here, poi.node, closed) is None
        ):
            if not closed or graph.search(here, poi.node, closed) is not None:
                skipped.append(poi.id)
            continue
        here = poi.node
    return skipped


def step_free_warnings(site: Site) -> list[SiteIssue]:
    """Warnings (not errors): each point only steps lead to, and each stop a step-free tour
    skips."""
    if not any(e.steps for e in site.edges):
        return []
    graph = SiteGraph(site, warm=False, tables=False)
    cut = steps_only_nodes(graph)
    return [
        SiteIssue(f"pois[{i}]", f"only steps lead to {poi.id!r}: a step-free visit is refused")
        for i, poi in enumerate(site.pois)
        if poi.node in cut
    ] + [
        SiteIssue(
            f"tours[{i}].points",
            f"a step-free tour of {tour.id!r} skips {poi!r}: only steps lead there",
        )
        for i, tour in enumerate(site.tours)
        for poi in step_free_skips(site, graph, tour)
    ]
