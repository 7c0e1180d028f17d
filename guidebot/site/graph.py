"""The site's topological map as a routing graph: shortest paths across floors.

Edges come from the site (two-way unless one-way); each elevator adds edges between its stops
costing its travel time at a nominal speed. Paths to the site's usual destinations walk down a
precomputed distance field. Between nodes that only an elevator ride connects (floors apart),
the path is read, not searched: distances to and from every elevator stop are kept, the best
stop is the minimum of (start to stop) + (stop to goal), and both halves are walked down those
distance fields (transit nodes; exact, a fraction of a millisecond). Between two nodes of one
floor, SciPy's compiled Dijkstra searches that floor alone (guidebot/site/floor_paths.py),
stopped at an upper bound of the answer: the best way through an elevator stop (riding up
and back might be shorter) or the best detour through a landmark, d(start, L) + d(L, goal),
whichever is smaller. Lengths are exact sums of edge costs; round them only for display.
Building takes seconds on a 10 000-node site, nearly all of it the tables
(guidebot/route_tables.py): the server builds the structure in a thread (``tables=False``),
has ``plan()`` computed in worker processes, ``install``s the answer and swaps
(backend/site/graph_build.py).
"""

from __future__ import annotations

import heapq
import math
from array import array
from collections.abc import Container, Iterable
from dataclasses import dataclass, field

from guidebot.route_tables import TablePlan, Tables, Topology, compute_tables, dijkstra
from guidebot.site.floor_paths import FloorPaths
from guidebot.site.schema import Site
from guidebot.site.steps import PathStep
from guidebot.site.validate import cabin_through_ways

__all__ = ["NoPath", "PathResult", "PathStep", "SiteGraph", "UnknownNode"]

NOMINAL_SPEED_MPS = 0.7
LANDMARKS = 12
"""Landmarks whose distances bound a floor search from above (each costs two Dijkstra searches
at build time)."""
UPPER_BOUND_SLACK = 1e-9
"""Relative margin on a floor search's upper bound: a bound summed in another order than the
path may come out a rounding error below the path's own length."""


class NoPath(LookupError):
    """The target cannot be reached from the start (one-way edges, disconnected floors)."""


class UnknownNode(KeyError):
    """A node id the site does not have."""


@dataclass(frozen=True, slots=True)
class PathResult:
    nodes: list[str]
    length_m: float
    steps: list[PathStep] = field(default_factory=list)

    @property
    def areas(self) -> list[str]:
        """Restricted areas in the order the path enters them."""
        out: list[str] = []
        for step in self.steps:
            if step.area is not None and (not out or out[-1] != step.area):
                out.append(step.area)
        return out


class SiteGraph:
    """Built once per site version; read-only afterwards (rebuild on site change)."""

    def __init__(
        self,
        site: Site,
        *,
        nominal_speed_mps: float = NOMINAL_SPEED_MPS,
        warm: bool = True,
        landmarks: int = LANDMARKS,
        tables: bool = True,
    ) -> None:
        """``tables=False``: the structure only; compute ``plan()`` elsewhere and ``install``
        the answer before the first query."""
        self.floor_of: dict[str, str] = {}
        self.xy: dict[str, tuple[float, float]] = {}
        self.passing: set[str] = set()
        for n in site.nodes:
            self.floor_of[n.id] = n.floor
            self.xy[n.id] = (n.x, n.y)
            if n.passing_place:
                self.passing.add(n.id)
        self.adj: dict[str, list[tuple[str, float]]] = {n: [] for n in self.floor_of}
        self.radj: dict[str, list[tuple[str, float]]] = {n: [] for n in self.floor_of}
        # A cabin node is entered only to ride: edges that make it a through-way are not used.
        through = {way.edge for way in cabin_through_ways(site)}
        self.step_edges: set[tuple[str, str]] = set()
        """(from, to) of the edges with steps (``Edge.steps``): not for a step-free tour."""
        for i, e in enumerate(site.edges):
            if i in through:
                continue
            length = e.length_m if e.length_m is not None else max(self._dist(e.a, e.b), 1e-6)
            self._add(e.a, e.b, length)
            if not e.one_way:
                self._add(e.b, e.a, length)
            if e.steps:
                self.step_edges.update({(e.a, e.b), (e.b, e.a)})
        self.door_at = {d.node: d.id for d in site.doors}
        self.elevator_at: dict[str, str] = {}
        for el in site.elevators:
            cost = el.travel_time_s * nominal_speed_mps
            for s in el.stops:
                self.elevator_at[s.node] = el.id
            for s in el.stops:
                for t in el.stops:
                    if s.node != t.node:
                        self._add(s.node, t.node, cost)
        self.area_at: dict[str, str] = {}
        self.area_nodes: dict[str, list[str]] = {}
        self.area_passing: dict[str, str | None] = {}
        for a in site.areas:
            self.area_nodes[a.id] = list(a.nodes)
            self.area_passing[a.id] = a.passing_place
            for node in a.nodes:
                self.area_at[node] = a.id
        # Integer-indexed copies for the hot loops.
        self.names: list[str] = list(self.floor_of)
        self.index: dict[str, int] = {n: i for i, n in enumerate(self.names)}
        idx = self.index
        self._adj_i = [[(idx[b], c) for b, c in self.adj[n]] for n in self.names]
        self._radj_i = [[(idx[a], c) for a, c in self.radj[n]] for n in self.names]
        self._xs = [self.xy[n][0] for n in self.names]
        self._ys = [self.xy[n][1] for n in self.names]
        self._fields: dict[str, array[float]] = {}
        self._pinned: set[str] = set()
        self.field_cache_size = 256
        self._component = self._floor_components(set(self.elevator_at))
        self._floors = FloorPaths(self._adj_i, self._component)
        self._landmark_count = landmarks
        self._warm_goals = list(
            dict.fromkeys(
                n
                for n in [p.node for p in site.pois]
                + [c.node for c in site.charging_stations]
                + [w.node for w in site.wait_points]
                if warm and n in self.index
            )
        )
        # Landmarks: distance from each landmark to every node, and from every node to it.
        self._lm_from: list[array[float]] = []
        self._lm_to: list[array[float]] = []
        # Transit through elevators: distances to and from every elevator stop.
        self._transit: list[tuple[int, array[float], array[float]]] = []
        if tables:
            self.install(compute_tables(self.plan(), (self._adj_i, self._radj_i)))

    def plan(self) -> TablePlan:
        """The searches of this graph's tables: the landmarks, the elevator stops' fields and
        the usual destinations' fields (``compute_tables``, here or in another process)."""
        return TablePlan(
            Topology.of(self._adj_i, self._xs, self._ys),
            landmarks=self._landmark_count,
            stops=tuple(sorted(self.index[n] for n in self.elevator_at)),
            goals=tuple(self.index[n] for n in self._warm_goals),
        )

    def install(self, tables: Tables) -> None:
        """Take the tables computed for ``plan()`` (before the graph answers any query)."""
        self._lm_from, self._lm_to = tables.lm_from, tables.lm_to
        self._transit = tables.transit
        for goal, costs in tables.fields.items():
            name = self.names[goal]
            self._fields[name] = costs
            self._pinned.add(name)

    def _add(self, a: str, b: str, cost: float) -> None:
        self.adj[a].append((b, cost))
        self.radj[b].append((a, cost))

    def _dist(self, a: str, b: str) -> float:
        (ax, ay), (bx, by) = self.xy[a], self.xy[b]
        return math.hypot(ax - bx, ay - by)

    def __contains__(self, node: object) -> bool:
        return node in self.floor_of

    def check(self, *nodes: str | None) -> None:
        for node in nodes:
            if node is None or node not in self.floor_of:
                raise UnknownNode(node)

    def shortest_path(self, start: str, goal: str) -> PathResult:
        """The shortest path from start to goal; raises UnknownNode or NoPath."""
        self.check(start, goal)
        if start == goal:
            return PathResult([start], 0.0, [self.step(start)])
        field = self._fields.get(goal)
        if field is not None:
            return self._descend(start, goal, field)
        s, g = self.index[start], self.index[goal]
        if self._transit and self._component[s] != self._component[g]:
            return self._via_transit(s, g)
        return self._on_floor(s, g)

    def uses_steps(self, path: PathResult) -> bool:
        """Whether ``path`` takes an edge with steps."""
        return bool(self.step_edges) and any(
            (a, b) in self.step_edges for a, b in zip(path.nodes, path.nodes[1:], strict=False)
        )

    def step_free_path(
        self, start: str, goal: str, closed: Container[str] = frozenset()
    ) -> PathResult | None:
        """The shortest path from ``start`` to ``goal`` over no edge with steps and no node in
        ``closed`` (``start`` excepted); None when there is none. A plain search (Dijkstra): it
        is asked only for a step-free tour's legs whose shortest path has steps."""
        self.check(start, goal)
        found = self.search(start, goal, closed, self.step_edges)
        if found is None:
            return None
        nodes, length = found
        return PathResult(nodes, length, [self.step(n) for n in nodes])

    def search(
        self,
        start: str,
        goal: str,
        closed: Container[str] = frozenset(),
        closed_edges: Container[tuple[str, str]] = frozenset(),
    ) -> tuple[list[str], float] | None:
        """The shortest (nodes, length) from ``start`` to ``goal`` over no node in ``closed``
        (``start`` excepted) and no edge in ``closed_edges``; None when there is none. A plain
        Dijkstra on node names: for the rare searches round something (closures, steps), not
        the planner's fast path."""
        dist: dict[str, float] = {start: 0.0}
        prev: dict[str, str] = {}
        heap = [(0.0, start)]
        while heap:
            d, node = heapq.heappop(heap)
            if node == goal:
                nodes = [goal]
                while nodes[-1] != start:
                    nodes.append(prev[nodes[-1]])
                nodes.reverse()
                return nodes, d
            if d > dist.get(node, math.inf):
                continue
            for nxt, cost in self.adj.get(node, ()):
                if nxt in closed or (node, nxt) in closed_edges:
                    continue
                if d + cost < dist.get(nxt, math.inf):
                    dist[nxt] = d + cost
                    prev[nxt] = node
                    heapq.heappush(heap, (d + cost, nxt))
        return None

    def _floor_components(self, stops: set[str]) -> list[int]:
        """Component of each node over the edges that are not elevator rides (undirected):
        a path between two components must ride an elevator, so passes an elevator stop."""
        comp = [-1] * len(self.names)
        rides = {(a, b) for a in stops for b in stops}
        adj = self._adj_i
        undirected: list[list[int]] = [[] for _ in self.names]
        for a, out in enumerate(adj):
            for b, _ in out:
                if (self.names[a], self.names[b]) not in rides:
                    undirected[a].append(b)
                    undirected[b].append(a)
        label = 0
        for root in range(len(comp)):
            if comp[root] >= 0:
                continue
            comp[root] = label
            stack = [root]
            while stack:
                for nxt in undirected[stack.pop()]:
                    if comp[nxt] < 0:
                        comp[nxt] = label
                        stack.append(nxt)
            label += 1
        return comp

    def _best_stop(
        self, s: int, g: int
    ) -> tuple[float, tuple[int, array[float], array[float]] | None]:
        """The shortest path from ``s`` to ``g`` through an elevator stop: its length and stop
        (inf and None when no stop is on a way between them)."""
        best, via = math.inf, None
        for entry in self._transit:
            total = entry[1][s] + entry[2][g]
            if total < best:
                best, via = total, entry
        return best, via

    def _via_transit(self, s: int, g: int) -> PathResult:
        """Exact path through an elevator stop: the best of (s to a stop) + (that stop to g)
        over the stops, both read from the stops' precomputed distances, then walked down and
        up those distance fields. Exact between nodes that only an elevator ride connects:
        every path between them passes a stop."""
        return self._through_stop(s, g, *self._best_stop(s, g))

    def _through_stop(
        self, s: int, g: int, best: float, via: tuple[int, array[float], array[float]] | None
    ) -> PathResult:
        """The path of ``_best_stop``'s answer: down to the stop, then up to ``g``."""
        if via is None:
            raise NoPath(f"no path from {self.names[s]} to {self.names[g]}")
        stop, to_stop, from_stop = via
        first = self._walk(s, stop, to_stop, self._adj_i)
        second = self._walk(g, stop, from_stop, self._radj_i)
        second.reverse()
        return self._result(first + second[1:], best)

    def _on_floor(self, s: int, g: int) -> PathResult:
        """Between two nodes of one floor: the floor's own shortest path, unless riding an
        elevator is shorter (a corridor closed off on this floor). The floor search stops at
        the smaller of the two upper bounds, the best transit and the landmarks' detour."""
        via_stop, stop = self._best_stop(s, g)
        detour = min(
            (
                to_lm[s] + from_lm[g]
                for from_lm, to_lm in zip(self._lm_from, self._lm_to, strict=True)
            ),
            default=math.inf,
        )
        bound = min(via_stop, detour)
        found = self._floors.search(s, g, bound * (1 + UPPER_BOUND_SLACK) + UPPER_BOUND_SLACK)
        if found is None or found[1] > via_stop:
            return self._through_stop(s, g, via_stop, stop)
        return self._result(*found)

    def _result(self, path: list[int], length: float) -> PathResult:
        """The answer for a path of node indexes: names and each node's step."""
        nodes = [self.names[i] for i in path]
        return PathResult(nodes, length, [self.step(n) for n in nodes])

    def _walk(
        self, s: int, g: int, field: array[float], adj: list[list[tuple[int, float]]]
    ) -> list[int]:
        """From ``s`` to ``g`` down ``field`` (cost to ``g`` over ``adj``): each step takes an
        edge on a shortest path. Given the reverse lists and a field of costs from ``g``, this
        walks a shortest path from ``g`` to ``s`` backwards."""
        if field[s] == math.inf:
            raise NoPath(f"no path between {self.names[s]} and {self.names[g]}")
        path = [s]
        node = s
        limit = len(self.names)
        while node != g:
            here = field[node]
            best, best_left = -1, math.inf
            for nxt, cost in adj[node]:
                left = cost + field[nxt]
                if left < best_left:
                    best, best_left = nxt, left
            if best < 0 or best_left > here + 1e-6 or len(path) > limit:
                raise NoPath(f"no path between {self.names[s]} and {self.names[g]}")
            path.append(best)
            node = best
        return path

    def step(self, node: str) -> PathStep:
        x, y = self.xy[node]
        return PathStep(
            node=node,
            floor=self.floor_of[node],
            x=x,
            y=y,
            door=self.door_at.get(node),
            elevator=self.elevator_at.get(node),
            area=self.area_at.get(node),
        )

    def _field(self, goal: str) -> array[float]:
        """Cost from every node to ``goal``: one reverse Dijkstra, cached per goal."""
        field = self._fields.get(goal)
        if field is not None:
            return field
        self.check(goal)
        field = dijkstra(self.index[goal], self._radj_i)
        unpinned = [k for k in self._fields if k not in self._pinned]
        if len(unpinned) >= self.field_cache_size:
            del self._fields[unpinned[0]]
        self._fields[goal] = field
        return field

    def _descend(self, start: str, goal: str, field: array[float]) -> PathResult:
        """Follow the distance field downhill: each step takes the edge on a shortest path."""
        s, g = self.index[start], self.index[goal]
        return self._result(self._walk(s, g, field, self._adj_i), field[s])

    def distances_to(self, goal: str) -> _FieldView:
        """Path cost from every node to ``goal`` (mapping node -> metres; cached per goal).

        The Task Manager ranks robots by this: one search per task target, not per robot.
        """
        return _FieldView(self.index, self._field(goal))

    def passing_place_for(self, area: str, near: Iterable[str] = ()) -> str | None:
        """Where a robot yielding ``area`` should go: the area's own, else the nearest marked
        passing place outside it (breadth-first from the area), else any node next to it."""
        own = self.area_passing.get(area)
        if own is not None:
            return own
        inside = set(self.area_nodes.get(area, ()))
        start = [*near, *self.area_nodes.get(area, ())]
        seen = set(start)
        frontier = list(start)
        first_outside: str | None = None
        while frontier:
            nxt: list[str] = []
            for node in frontier:
                for other, _ in (*self.adj.get(node, ()), *self.radj.get(node, ())):
                    if other in seen:
                        continue
                    seen.add(other)
                    if other in inside:
                        nxt.append(other)
                        continue
                    if other in self.passing:
                        return other
                    if first_outside is None:
                        first_outside = other
                    nxt.append(other)
            frontier = nxt
        return first_outside


class _FieldView:
    """Read-only mapping view of a distance field by node name."""

    __slots__ = ("_field", "_index")

    def __init__(self, index: dict[str, int], field: array[float]) -> None:
        self._index = index
        self._field = field

    def get(self, node: str | None, default: float | None = None) -> float | None:
        i = self._index.get(node) if node is not None else None
        if i is None:
            return default
        value = self._field[i]
        return default if value == math.inf else value

    def __getitem__(self, node: str) -> float:
        value = self.get(node)
        if value is None:
            raise KeyError(node)
        return value
