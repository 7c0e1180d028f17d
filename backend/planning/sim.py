"""A day of tour requests played over a simulated fleet in simulated time: no processes, no
sleeping. It reuses the product's pure cores: the Task Manager's robot choice
(``backend.tasks.choice.choose_robot``), the ETA model's nominal tour segments
(``backend.tasks.eta.EtaEstimator`` behind its Fleet protocol: path lengths on the site graph
with elevator rides, speech and facing people at each point, the "continue?" question) and the
site's robot speeds. docs/planning.md says what it leaves out."""

from __future__ import annotations

import heapq
import math
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from backend.planning.profile import Pace, PlanError, Request
from backend.tasks.choice import choose_robot, idle_errands
from backend.tasks.eta import EtaEstimator, Segment
from backend.tasks.model import Task
from backend.tasks.queue import TaskQueue
from backend.tasks.robots import RobotInfo
from backend.tasks.targets import target_node
from guidebot.site.graph import SiteGraph
from guidebot.site.schema import RobotConfig, Site

__all__ = ["POLICIES", "Outcome", "Pace", "fleet", "nominal_segments", "simulate"]

POLICIES = ("nearest", "longest-idle")
"""nearest: the Task Manager's own choice (cheapest to reach the tour's first point);
longest-idle: the robot that has waited longest (a plain rotation, for comparison)."""


class _Fleet:
    """The read-only view ``EtaEstimator`` needs (its Fleet protocol), over the simulation."""

    def __init__(self, site: Site, graph: SiteGraph, robots: Mapping[str, RobotInfo]) -> None:
        self._site, self._graph, self._robots = site, graph, robots
        self._tasks: dict[str, Task] = {}
        self._queue = TaskQueue(1)
        self.now = 0.0

    @property
    def clock(self) -> Callable[[], float]:
        return lambda: self.now

    @property
    def site(self) -> Site:
        return self._site

    @property
    def graph(self) -> SiteGraph:
        return self._graph

    @property
    def robots(self) -> Mapping[str, RobotInfo]:
        return self._robots

    @property
    def tasks(self) -> Mapping[str, Task]:
        return self._tasks

    @property
    def queue(self) -> TaskQueue:
        return self._queue

    def has_free_robot(self) -> bool:
        return True

    def target_of(self, kind: str, params: dict[str, Any]) -> str:
        return target_node(self._site, self._graph, kind, params)

    def lift_wait_s(self, start: str | None, goal: str) -> float:
        """No lift queue in the plan (a ride is travel time: docs/planning.md, "Not modelled")."""
        return 0.0


def nominal_segments(site: Site, graph: SiteGraph, tour: str, start: str | None) -> list[Segment]:
    """The ETA model's nominal segments of ``tour`` for a robot starting at ``start``."""
    robots = fleet(site, 1)
    task = Task(id="nominal", kind="tour", params={"tour": tour}, priority=0, requester="", seq=0)
    task.robot = next(iter(robots))
    return EtaEstimator(_Fleet(site, graph, robots)).segments(task, start)


def fleet(site: Site, size: int) -> dict[str, RobotInfo]:
    """``size`` robots: the site's own first (their speeds and start nodes), then copies of the
    last one's settings starting at the charging stations and wait points in turn."""
    configs = list(site.robots[:size])
    homes = [c.node for c in site.charging_stations] + [w.node for w in site.wait_points]
    homes = homes or [site.nodes[0].id]
    base = site.robots[-1] if site.robots else None
    for i in range(len(configs), size):
        configs.append(
            RobotConfig(
                name=f"P{i + 1}",
                token="planning-robot",
                start_node=homes[i % len(homes)],
                max_speed_mps=base.max_speed_mps if base else 0.7,
            )
        )
    robots = {}
    for i, config in enumerate(configs):
        node = config.start_node or homes[i % len(homes)]
        robots[config.name] = RobotInfo(name=config.name, config=config, online=True, node=node)
    return robots


@dataclass
class Outcome:
    """One simulated day at one fleet size under one policy."""

    robots: int
    policy: str
    requests: int
    waits_s: list[float] = field(default_factory=list)
    """Request to the robot's arrival at the tour's first point, per served request."""
    wait_of: dict[int, float] = field(default_factory=dict)
    """The same waits by the request's index."""
    refused: int = 0
    abandoned: int = 0
    busy_s: float = 0.0
    day_s: float = 0.0
    last_end_s: float = 0.0
    wall_s: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)
    """What only a live run measures (``backend.planning.live``): lock and elevator waits..."""

    def summary(self, within_min: float) -> dict[str, Any]:
        waits = sorted(self.waits_s)
        within = sum(1 for w in waits if w <= within_min * 60)
        span = max(self.day_s, self.last_end_s)
        return {
            "robots": self.robots,
            "policy": self.policy,
            "requests": self.requests,
            "served": len(waits),
            "refused": self.refused,
            "abandoned": self.abandoned,
            "wait_p50_s": _round(quantile(waits, 0.50)),
            "wait_p95_s": _round(quantile(waits, 0.95)),
            "wait_max_s": _round(waits[-1] if waits else None),
            "within_min": within_min,
            "served_within_share": round(within / self.requests, 3) if self.requests else None,
            "tours_per_hour": round(len(waits) / (self.day_s / 3600), 2) if self.day_s else None,
            "utilisation": round(self.busy_s / (self.robots * span), 3) if span else 0.0,
            "last_tour_ends_h": round(self.last_end_s / 3600, 2),
            "wall_s": round(self.wall_s, 3),
            **self.extra,
        }


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 1)


def quantile(ordered: Sequence[float], q: float) -> float | None:
    """The nearest-rank ``q`` quantile of sorted values (None when there are none)."""
    if not ordered:
        return None
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


def _tour_time(
    segments: list[Segment], follow: int, pace: Pace = Pace()
) -> tuple[float, float, int]:
    """(seconds to the first point, seconds of the whole task, index of the last point) when
    the visitors follow ``follow`` points (the tour ends after that point's explanation)."""

    def real(s: Segment) -> float:
        return s.nominal_s * (pace.move if s.kind == "move" else pace.talk)

    first = real(segments[0]) if segments else 0.0
    taken = [s for s in segments if s.index <= follow]
    return first, sum(real(s) for s in taken), max((s.index for s in taken), default=1)


def simulate(
    site: Site,
    graph: SiteGraph,
    requests: Sequence[Request],
    *,
    robots: int,
    policy: str = "nearest",
    day_s: float,
    patience_s: float | None = None,
    queue_limit: int | None = None,
    pace: Pace = Pace(),
) -> Outcome:
    """Play ``requests`` (time order) over ``robots`` robots; the queue is first come, first
    served, as the Task Manager's for tours of one priority. A request is refused when
    ``queue_limit`` already wait, and abandoned when it waited ``patience_s`` for a robot.
    ``pace`` scales the nominal legs and explanations (a recording's, ``recorded.learn_pace``)."""
    if policy not in POLICIES:
        raise PlanError(f"unknown policy {policy!r}; known: {', '.join(POLICIES)}")
    if robots < 1:
        raise PlanError(f"a fleet needs at least one robot (got {robots})")
    started = time.perf_counter()
    fleet_now = fleet(site, robots)
    view = _Fleet(site, graph, fleet_now)
    eta = EtaEstimator(view)
    out = Outcome(robots=robots, policy=policy, requests=len(requests), day_s=day_s)
    free: dict[str, RobotInfo] = dict(fleet_now)
    idle_since = {name: 0.0 for name in free}
    waiting: deque[int] = deque()
    queued: set[int] = set()
    """Requests still waiting (``waiting`` also holds those that left, skipped when reached)."""
    gone: set[int] = set()
    events: list[tuple[float, int, int, str, str]] = []
    """(time, order, request index or -1, kind, robot name)"""
    order = 0
    for i, req in enumerate(requests):
        events.append((req.at, order, i, "arrive", ""))
        order += 1
    heapq.heapify(events)
    points_of: dict[str, list[str]] = {}
    for tour in site.tours:
        nodes = [p.node for p in (site.poi(i) for i in tour.points) if p is not None]
        points_of[tour.id] = nodes
    parking: dict[str, tuple[int, float, str]] = {}
    """robot -> (order of its "parked" event, when it gets there, where): driving to park."""
    while events:
        now, _, i, kind, name = heapq.heappop(events)
        view.now = now
        if kind == "arrive":
            if queue_limit is not None and len(queued) >= queue_limit:
                out.refused += 1
            else:
                waiting.append(i)
                queued.add(i)
                if patience_s is not None:
                    heapq.heappush(events, (now + patience_s, order, i, "leave", ""))
                    order += 1
        elif kind == "leave":
            if i in queued:
                queued.discard(i)
                gone.add(i)
                out.abandoned += 1
        elif kind == "parked":
            trip = parking.get(name)
            if trip is not None and trip[0] == i:  # not called away on the way
                fleet_now[name].node = parking.pop(name)[2]
        else:  # a robot is free again
            free[name] = fleet_now[name]
            idle_since[name] = now
        while waiting and free:
            i = waiting.popleft()
            if i in gone:
                gone.discard(i)
                continue
            queued.discard(i)
            req = requests[i]
            task = Task(
                id=f"t{i}",
                kind="tour",
                params={"tour": req.tour},
                priority=0,
                requester="planning",
                seq=i,
                created_at=req.at,
            )
            robot = _pick(policy, task, free, idle_since, graph, points_of[req.tour])
            if robot is None:  # no free robot can reach it: it waits for the next one
                waiting.appendleft(i)
                queued.add(i)
                break
            task.robot = robot.name
            first, took, last = _tour_time(eta.segments(task, robot.node), req.follow, pace)
            out.waits_s.append(now - req.at + first)
            out.wait_of[i] = out.waits_s[-1]
            out.busy_s += took
            del free[robot.name]
            parking.pop(robot.name, None)
            robot.node = points_of[req.tour][last - 1]
            end = now + took
            out.last_end_s = max(out.last_end_s, end)
            heapq.heappush(events, (end, order, -1, "free", robot.name))
            order += 1
        for robot in list(free.values()):
            if robot.name in parking or kind not in ("free", "parked"):
                continue
            park = _park(robot, fleet_now, parking, site, graph)
            if park is not None:
                parking[robot.name] = (order, now + park[1], park[0])
                heapq.heappush(events, (now + park[1], order, order, "parked", robot.name))
                order += 1
    out.wall_s = time.perf_counter() - started
    return out


def _park(
    robot: RobotInfo,
    fleet_now: Mapping[str, RobotInfo],
    parking: Mapping[str, tuple[int, float, str]],
    site: Site,
    graph: SiteGraph,
) -> tuple[str, float] | None:
    """Where an idle robot goes and how long it drives there: the Task Manager's own rule
    (``idle_errands``: a free charging station, else the nearest wait point), None if it
    stays."""
    at = {s.node: s.id for s in site.charging_stations}
    claimed = [at.get(where) for _, _, where in parking.values()]
    errands = idle_errands(
        [robot], fleet_now.values(), claimed, site, graph.distances_to, lambda _: False
    )
    if not errands:
        return None
    _, kind, params = errands[0]
    node = params["node"] if kind == "go_to" else _station_node(site, params["station"])
    metres = graph.distances_to(node).get(robot.node)
    if metres is None or robot.node is None:
        return None
    return node, metres / robot.config.max_speed_mps


def _station_node(site: Site, station: str) -> str:
    return next(s.node for s in site.charging_stations if s.id == station)


def _pick(
    policy: str,
    task: Task,
    free: Mapping[str, RobotInfo],
    idle_since: Mapping[str, float],
    graph: SiteGraph,
    points: list[str],
) -> RobotInfo | None:
    if policy == "longest-idle":
        return min(free.values(), key=lambda r: (idle_since[r.name], r.name))
    return choose_robot(task, free, lambda: graph.distances_to(points[0]))
