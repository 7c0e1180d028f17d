"""Paths that avoid closed nodes (building modes and trouble, backend/closures).

The site graph's own search (guidebot/site/graph.py) knows nothing of closures: its answer is
taken when it crosses no closed node, else a Dijkstra over the graph without the closed nodes
finds the way around. A goal that is itself closed, or that only closed nodes lead to, raises
``RouteClosed`` naming the closures that cut it off (what the visitor is told)."""

from __future__ import annotations

from collections.abc import Mapping

from backend.closure import Closure
from guidebot.site.graph import NoPath, PathResult, SiteGraph

__all__ = ["RouteClosed", "StepsOnly", "path_avoiding", "step_free_path_of"]


class RouteClosed(NoPath):
    """No way to the goal but through closed elements."""

    def __init__(self, goal: str, closures: list[Closure]) -> None:
        self.goal = goal
        self.closures = closures
        super().__init__(f"{goal} cut off: {self.reason}")

    @property
    def reason(self) -> str:
        """Why, for the visitor, one part per closure joined by "; ": "<gallery|door|elevator|
        nodes> <id> closed: <staff's words>" or, for trouble, "<door|elevator> <id> out of
        order" (docs/protocol.md, "Skipped stops": pages put it in the visitor's language)."""
        return "; ".join(
            f"{c.what()} out of order"
            if c.source == "trouble"
            else f"{c.what()} closed: {c.reason}"
            for c in self.closures
        )

    @property
    def trouble(self) -> bool:
        """Only trouble cuts it off (a jammed door, a stuck lift), no closure by staff: the
        ``path`` answer's ``trouble`` flag, on which a robot waits for the way to clear."""
        return bool(self.closures) and all(c.source == "trouble" for c in self.closures)


class StepsOnly(RouteClosed):
    """No way to the goal for a step-free tour but over steps (``Edge.steps``): the reason is
    ``steps`` (docs/protocol.md, "Skipped stops")."""

    def __init__(self, goal: str) -> None:
        super().__init__(goal, [])

    @property
    def reason(self) -> str:
        return "steps"


def step_free_path_of(
    graph: SiteGraph, found: PathResult, closed: Mapping[str, Closure]
) -> PathResult:
    """``found`` when it takes no steps, else the shortest step-free path between its ends
    avoiding ``closed`` (StepsOnly when there is none)."""
    if not graph.uses_steps(found):
        return found
    start, goal = found.nodes[0], found.nodes[-1]
    better = graph.step_free_path(start, goal, closed)
    if better is None:
        raise StepsOnly(goal)
    return better


def path_avoiding(
    graph: SiteGraph, start: str, goal: str, closed: Mapping[str, Closure]
) -> PathResult:
    """The shortest path from ``start`` to ``goal`` over open nodes (``start`` may be closed: a
    robot inside a closed gallery gets out). Raises UnknownNode, NoPath, or RouteClosed."""
    plain = graph.shortest_path(start, goal)  # UnknownNode / NoPath as without closures
    if not closed:
        return plain
    if goal in closed and goal != start:
        raise RouteClosed(goal, [closed[goal]])
    if not any(n in closed for n in plain.nodes[1:]):
        return plain
    found = graph.search(start, goal, closed)
    if found is None:
        cut = list({id(c): c for n in plain.nodes[1:] if (c := closed.get(n))}.values())
        raise RouteClosed(goal, cut)
    nodes, length = found
    return PathResult(nodes, length, [graph.step(n) for n in nodes])
