"""The route graph's precomputed tables (landmarks, elevator-stop distances, destination
distance fields): many Dijkstra searches over one topology, independent of each other.

They are pure functions of integer arrays, so a server can compute them in other processes
(``split`` a plan, run ``compute_tables`` on each part, ``merge`` the answers) while its event
loop keeps serving: in a thread they would take the GIL from the loop for seconds. This module
imports only the standard library so that a spawned worker starts fast.
"""

from __future__ import annotations

import heapq
import math
from array import array
from dataclasses import dataclass, field

__all__ = [
    "Adjacency",
    "TablePlan",
    "Tables",
    "Topology",
    "choose_landmarks",
    "compute_tables",
    "dijkstra",
    "merge",
    "split",
]

Adjacency = list[list[tuple[int, float]]]
"""Per node index, its (neighbour index, cost) edges."""


@dataclass(frozen=True)
class Topology:
    """The graph as flat arrays (compressed rows): a few hundred kilobytes on a 10 000-node
    site, sent to a worker process as a handful of memory copies."""

    offsets: array[int]
    targets: array[int]
    costs: array[float]
    xs: array[float]
    ys: array[float]

    @classmethod
    def of(cls, adj: Adjacency, xs: list[float], ys: list[float]) -> Topology:
        offsets, targets, costs = array("q", [0]), array("q"), array("d")
        for out in adj:
            for node, cost in out:
                targets.append(node)
                costs.append(cost)
            offsets.append(len(targets))
        return cls(offsets, targets, costs, array("d", xs), array("d", ys))

    def adjacency(self) -> tuple[Adjacency, Adjacency]:
        """The forward and reverse lists the searches walk."""
        n = len(self.offsets) - 1
        fwd: Adjacency = [[] for _ in range(n)]
        rev: Adjacency = [[] for _ in range(n)]
        offsets, targets, costs = self.offsets, self.targets, self.costs
        for a in range(n):
            out = fwd[a]
            for k in range(offsets[a], offsets[a + 1]):
                b, cost = targets[k], costs[k]
                out.append((b, cost))
                rev[b].append((a, cost))
        return fwd, rev


@dataclass(frozen=True)
class TablePlan:
    """What to compute: ``landmarks`` landmarks, both distance fields of each elevator
    stop in ``stops`` and the field to each node of ``goals`` (all as node indexes)."""

    topology: Topology
    landmarks: int = 0
    stops: tuple[int, ...] = ()
    goals: tuple[int, ...] = ()

    @property
    def searches(self) -> int:
        """Dijkstra searches the plan costs (the measure of its work)."""
        return 2 * self.landmarks + 2 * len(self.stops) + len(self.goals)


@dataclass
class Tables:
    """Landmark fields (from and to each), per stop (index, cost to it, cost from it), and per
    goal index the cost to it from every node."""

    lm_from: list[array[float]] = field(default_factory=list)
    lm_to: list[array[float]] = field(default_factory=list)
    transit: list[tuple[int, array[float], array[float]]] = field(default_factory=list)
    fields: dict[int, array[float]] = field(default_factory=dict)


def dijkstra(source: int, adj: Adjacency) -> array[float]:
    """Costs from ``source`` over ``adj`` (or, given the reverse lists, to ``source``)."""
    dist = [math.inf] * len(adj)
    dist[source] = 0.0
    heap = [(0.0, source)]
    pop, push = heapq.heappop, heapq.heappush
    while heap:
        d, node = pop(heap)
        if d > dist[node]:
            continue
        for nxt, cost in adj[node]:
            nd = d + cost
            if nd < dist[nxt]:
                dist[nxt] = nd
                push(heap, (nd, nxt))
    return array("d", dist)


def choose_landmarks(
    fwd: Adjacency, rev: Adjacency, xs: array[float], ys: array[float], count: int
) -> tuple[list[array[float]], list[array[float]]]:
    """Farthest-point landmarks: each new one is the node farthest (by path cost, among those
    reachable) from the landmarks already chosen, so they sit on the map's rim. Returns the
    costs from and to each landmark."""
    n = len(fwd)
    lm_from: list[array[float]] = []
    lm_to: list[array[float]] = []
    if n < 3 or count < 1:
        return lm_from, lm_to
    nearest = [math.inf] * n
    landmark = max(range(n), key=lambda i: xs[i] + ys[i])
    for _ in range(min(count, n)):
        from_lm = dijkstra(landmark, fwd)
        lm_from.append(from_lm)
        lm_to.append(dijkstra(landmark, rev))
        best, landmark = -1.0, -1
        for i in range(n):
            d = from_lm[i]
            if d < nearest[i]:
                nearest[i] = d
            if nearest[i] != math.inf and nearest[i] > best:
                best, landmark = nearest[i], i
        if best <= 0.0:
            break
    return lm_from, lm_to


def compute_tables(plan: TablePlan, adjacency: tuple[Adjacency, Adjacency] | None = None) -> Tables:
    """Every search of the plan (``adjacency``: the lists, when the caller has them)."""
    fwd, rev = adjacency or plan.topology.adjacency()
    lm_from, lm_to = choose_landmarks(fwd, rev, plan.topology.xs, plan.topology.ys, plan.landmarks)
    return Tables(
        lm_from,
        lm_to,
        [(i, dijkstra(i, rev), dijkstra(i, fwd)) for i in plan.stops],
        {g: dijkstra(g, rev) for g in plan.goals},
    )


def split(plan: TablePlan, parts: int) -> list[TablePlan]:
    """The plan cut into about ``parts`` plans of similar work: the landmarks (a chain, each
    chosen from the last one's field) stay one piece; stops and goals are dealt out."""
    parts = max(1, parts)
    pieces = [TablePlan(plan.topology, landmarks=plan.landmarks)] if plan.landmarks else []
    jobs: list[tuple[str, int]] = [("stop", s) for s in plan.stops] + [
        ("goal", g) for g in plan.goals
    ]
    per_part = max(1, -(-len(jobs) // parts))
    for start in range(0, len(jobs), per_part):
        chunk = jobs[start : start + per_part]
        pieces.append(
            TablePlan(
                plan.topology,
                stops=tuple(i for kind, i in chunk if kind == "stop"),
                goals=tuple(i for kind, i in chunk if kind == "goal"),
            )
        )
    return pieces or [plan]


def merge(answers: list[Tables]) -> Tables:
    """The answers of a split plan as one (stops in the order they were planned)."""
    whole = Tables()
    for part in answers:
        whole.lm_from.extend(part.lm_from)
        whole.lm_to.extend(part.lm_to)
        whole.transit.extend(part.transit)
        whole.fields.update(part.fields)
    return whole
