"""Any-pair paths of the site graph are exact: against a plain Dijkstra, on floors joined only
by elevators (the transit search) and within a floor (A* with landmarks)."""

from __future__ import annotations

import heapq
import itertools
import math
import random

import pytest

from guidebot.site import validate_site
from guidebot.site.graph import NoPath, SiteGraph
from guidebot.site.synthetic import synthetic_site


def reference_length(graph: SiteGraph, start: str, goal: str) -> float:
    dist = {start: 0.0}
    heap = [(0.0, start)]
    while heap:
        d, node = heapq.heappop(heap)
        if node == goal:
            return d
        if d > dist[node]:
            continue
        for nxt, cost in graph.adj[node]:
            if d + cost < dist.get(nxt, math.inf):
                dist[nxt] = d + cost
                heapq.heappush(heap, (d + cost, nxt))
    return math.inf


def walked_length(graph: SiteGraph, nodes: list[str]) -> float:
    total = 0.0
    for a, b in itertools.pairwise(nodes):
        total += min(c for n, c in graph.adj[a] if n == b)  # ValueError if not an edge
    return total


def one_way_site() -> dict[str, object]:
    """A three-floor synthetic site with some corridors made one-way."""
    doc = synthetic_site(nodes=300, robots=2, areas=2, pois=4, floors=3).model_dump(mode="json")
    rng = random.Random(3)
    for edge in rng.sample(doc["edges"], 60):
        if not edge["a"].startswith("lift") and not edge["b"].startswith("lift"):
            edge["one_way"] = True
    return doc


@pytest.mark.parametrize("one_way", [False, True])
def test_any_pair_paths_are_shortest_and_walkable(one_way: bool) -> None:
    doc = (
        one_way_site()
        if one_way
        else synthetic_site(nodes=300, robots=2, areas=2, pois=4, floors=3).model_dump(mode="json")
    )
    graph = SiteGraph(validate_site(doc), warm=False)
    names = list(graph.names)
    rng = random.Random(5)
    crossing = 0
    for _ in range(300):
        start, goal = rng.sample(names, 2)
        expected = reference_length(graph, start, goal)
        if expected == math.inf:
            with pytest.raises(NoPath):
                graph.shortest_path(start, goal)
            continue
        path = graph.shortest_path(start, goal)
        crossing += graph.floor_of[start] != graph.floor_of[goal]
        assert path.nodes[0] == start and path.nodes[-1] == goal
        assert path.length_m == pytest.approx(expected, rel=1e-12)
        assert walked_length(graph, path.nodes) == pytest.approx(expected, rel=1e-12)
    assert crossing > 100  # the transit search was exercised


def test_a_node_no_ride_reaches_is_no_path_from_another_floor() -> None:
    doc = synthetic_site(nodes=50, robots=1, areas=1, pois=2, floors=2).model_dump(mode="json")
    doc["nodes"].append({"id": "island", "floor": "F1", "x": 99, "y": 99})
    graph = SiteGraph(validate_site(doc), warm=False)
    with pytest.raises(NoPath):
        graph.shortest_path("n0_0_0", "island")
    with pytest.raises(NoPath):
        graph.shortest_path("island", "n0_1_1")
    assert graph.shortest_path("n0_0_0", "n1_1_1").nodes[-1] == "n1_1_1"
