"""Stops a closure cuts off (docs/visitor.md, "The wait"): a queued tour will skip not only the
stops whose own node is closed but every stop only closed nodes lead to. The robots start from
their docks and charging stations, so a stop is cut off when no open path leads to it from
there while one did with nothing closed (a site whose nodes some dock never reaches is not
counted against it)."""

from __future__ import annotations

from collections.abc import Collection, Iterable

from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site

__all__ = ["CutOff"]


class CutOff:
    """The nodes open paths reach from the robots' homes, cached per site and closure set
    (asked for every estimate: a walk of the graph only when the closures change)."""

    def __init__(self) -> None:
        self._key: tuple[int, frozenset[str]] | None = None
        self._cut: frozenset[str] = frozenset()
        self._whole: tuple[int, frozenset[str]] | None = None

    def cut_off(self, site: Site, graph: SiteGraph, closed: Collection[str]) -> frozenset[str]:
        """The nodes reachable with nothing closed that no open path reaches now (the closed
        nodes themselves included)."""
        key = (id(graph), frozenset(closed))
        if self._key != key:
            homes = _homes(site, graph)
            if self._whole is None or self._whole[0] != id(graph):
                self._whole = (id(graph), _reach(graph, homes, frozenset()))
            self._cut = self._whole[1] - _reach(graph, homes, key[1])
            self._key = key
        return self._cut


def _homes(site: Site, graph: SiteGraph) -> list[str]:
    nodes = [r.start_node for r in site.robots if r.start_node]
    nodes += [s.node for s in site.charging_stations]
    return [n for n in dict.fromkeys(nodes) if n in graph]


def _reach(graph: SiteGraph, sources: Iterable[str], closed: frozenset[str]) -> frozenset[str]:
    """Nodes reached from ``sources`` (a closed source still counts: a robot there gets out)
    over nodes not ``closed``."""
    seen = set(sources)
    todo = list(seen)
    while todo:
        for nxt, _ in graph.adj.get(todo.pop(), ()):
            if nxt not in seen and nxt not in closed:
                seen.add(nxt)
                todo.append(nxt)
    return frozenset(seen)
