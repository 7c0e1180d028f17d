"""Any-pair paths of the site graph are exact: against a plain Dijkstra, on floors joined only
by elevators (the transit search) and within a floor (the floor search, riding up and back
when that is shorter)."""

from __future__ import annotations

import heapq
import itertools
import math
import random

import pytest

from guidebot.site import validate_site
from guidebot.site.floor_paths import FloorPaths
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


def test_a_path_within_a_floor_rides_up_and_back_when_that_is_shorter() -> None:
    """F0's corridors are long, F1's short: from one lift's landing to the other's, the way
    over F1 (two rides) beats F0's own corridors, and the floor search must not keep F0's."""
    doc = synthetic_site(nodes=50, robots=1, areas=1, pois=2, floors=2).model_dump(mode="json")
    for edge in doc["edges"]:
        if edge["a"].startswith("n0_") and edge["b"].startswith("n0_"):
            edge["length_m"] = 100.0
    graph = SiteGraph(validate_site(doc), warm=False)
    start, goal = "n0_0_0", "n0_4_4"  # the landings of lift0 and lift1 on F0
    path = graph.shortest_path(start, goal)
    assert path.length_m == pytest.approx(reference_length(graph, start, goal), rel=1e-12)
    assert {graph.floor_of[n] for n in path.nodes} == {"F0", "F1"}
    assert walked_length(graph, path.nodes) == pytest.approx(path.length_m, rel=1e-12)
    # Two nodes one corridor apart stay on their floor.
    near = graph.shortest_path("n0_0_0", "n0_0_1")
    assert near.nodes == ["n0_0_0", "n0_0_1"] and near.length_m == 100.0


def test_one_floor_without_elevators_and_a_one_way_street() -> None:
    """No elevator (no transit bound): the search is bounded by the landmarks alone; a one-way
    street is not walked backwards."""
    doc = {
        "name": "hall",
        "floors": [{"id": "F0", "level": 0}],
        "nodes": [{"id": k, "floor": "F0", "x": float(i), "y": 0.0} for i, k in enumerate("abcde")],
        "edges": [
            {"a": "a", "b": "b", "length_m": 3.0},
            {"a": "b", "b": "c", "length_m": 2.0},
            {"a": "c", "b": "d", "length_m": 2.0, "one_way": True},
        ],
    }
    graph = SiteGraph(validate_site(doc), warm=False)
    forward = graph.shortest_path("a", "d")
    assert forward.nodes == ["a", "b", "c", "d"] and forward.length_m == 7.0
    with pytest.raises(NoPath):
        graph.shortest_path("d", "a")  # against the one-way street
    with pytest.raises(NoPath):
        graph.shortest_path("a", "e")  # a node no corridor reaches


def test_the_floor_search_takes_the_shorter_of_parallel_edges_and_honours_its_limit() -> None:
    """Sites refuse duplicate corridors, but an adjacency may still list two edges between the
    same nodes: the matrix keeps the shorter (SciPy would add them up)."""
    adj = [[(1, 3.0), (1, 5.0)], [(2, 2.0)], [], []]
    floors = FloorPaths(adj, [0, 0, 0, 1])
    assert floors.search(0, 2, math.inf) == ([0, 1, 2], 5.0)
    assert floors.search(0, 2, 4.9) is None  # longer than the caller's bound
    assert floors.search(2, 0, math.inf) is None  # no way back
    assert floors.search(0, 3, math.inf) is None  # another component
