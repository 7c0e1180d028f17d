"""Where a moving robot may be, for the Traffic Manager's releases (docs/server.md, "Lock
policy"): an area the robot may still be inside is never released on a guess.

A robot reports nodes (``node_reached`` on each, ``robot_state`` once a second); between two
reports it drives the edge from the last node to the next. So it may be inside the areas of
that node and of the next one: the next node of its known path, or any neighbour when its
path is not known (planned on board) or it has left it. The soak saw the server release a
corridor at a task's end from a position a second old, and the robot drive on through it
after another robot had been granted it (issue 36).
"""

from __future__ import annotations

from collections.abc import Iterable

from guidebot.site.graph import PathResult, SiteGraph

__all__ = ["areas_near", "claimed_areas"]


def areas_near(graph: SiteGraph, node: str | None, path: PathResult | None) -> set[str]:
    """The areas a robot last seen at ``node`` may be inside: ``node``'s and those of the
    next node of ``path`` (every neighbour's when ``node`` is not on it). Unknown node: all
    areas may be (the caller keeps what the robot holds)."""
    at = graph.area_at
    if node is None or node not in graph:
        return set(graph.area_nodes)
    near = {node}
    following = _next_nodes(path, node) if path is not None else None
    if following is None:
        following = [n for n, _ in graph.adj.get(node, ())]
        following += [n for n, _ in graph.radj.get(node, ())]
    near.update(following)
    return {at[n] for n in near if n in at}


def _next_nodes(path: PathResult, node: str) -> list[str] | None:
    """The nodes that follow ``node`` on ``path`` (it may pass a node twice); None when
    ``node`` is not on it."""
    nodes = path.nodes
    found = [nodes[i + 1] for i, n in enumerate(nodes) if n == node and i + 1 < len(nodes)]
    if found or node in nodes:
        return found
    return None


def claimed_areas(reported: object) -> set[str] | None:
    """The areas a robot says it holds (robot_state ``areas``), or None when it does not say
    (an older agent, an in-process vehicle): then only its position speaks for it."""
    if not isinstance(reported, list):
        return None
    items: Iterable[object] = reported
    return {a for a in items if isinstance(a, str)}
