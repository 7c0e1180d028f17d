"""Wait and duration estimates for visitors: when a robot will start on a task, when it will be
at the tour's first point, how long a running tour still takes, and whether any robot can serve
at all (docs/visitor.md, "The wait").

A task is a list of segments, each predicted in nominal robot seconds: legs (path length from
the site graph, elevator rides included, at the robot's speed, plus the continue question before
every leg but the first) and explanations (the spoken text at ~2.6 words/s plus facing people).
Two learned factors turn nominal into real seconds: one for legs, one for explanations, each the
running ratio real/predicted over the segments robots reported (``tour_progress``) and over
whole tasks that ended. So a fleet at another time scale, slower robots or chatty visitors are
learned from the first tour.

The wait of a queued task comes from simulating the queue in order over the working robots:
each robot is free after what it still has to do (its running task's remaining segments), at
the node where that ends; the next task in line goes to the robot free first. The simulation is
cached: a request joining the queue is simulated into it (at the tail: extended; ahead of others:
again from the last checkpoint before its place); any other change rebuilds it on the next
question, and it is never older than ``refresh_s``. The places of each tour and point are looked
up once per site, with the nominal seconds of all but the first leg (a rebuild over 10 000
queued tasks and 1 000 robots is ~0.06 s, was ~0.5 s).
"""

from __future__ import annotations

import bisect
import heapq
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, Protocol

from backend.tasks.battery_forecast import CHARGED, charge_first_s
from backend.tasks.charging import finish_floor
from backend.tasks.cutoff import CutOff
from backend.tasks.model import Task, TaskState
from guidebot.pace import Pace, pace_of
from guidebot.site.access import first_stops_skipped
from guidebot.site.i18n import poi_texts

if TYPE_CHECKING:
    from backend.tasks.queue import TaskQueue
    from backend.tasks.robots import RobotInfo
    from guidebot.site.graph import SiteGraph
    from guidebot.site.schema import Site

__all__ = ["Estimate", "EtaEstimator", "Fleet", "Service", "speech_s"]

WORDS_PER_SECOND = 2.6
"""Speaking rate of robot_agent.speech's timed fallback (espeak-ng's default is close)."""
FACE_AND_REST_S = 2.0
"""Facing people and the rest expression around each explanation (nominal)."""
QUESTION_S = 3.0
"""Waiting for the answer to "continue the tour?" before each next point (nominal)."""
CHARGE_S = 1800.0
"""A robot sent to charge comes back after this (until a charge has been timed)."""
UNKNOWN_TRAVEL_M = 50.0
"""A robot whose node is unknown is assumed this far from the target."""
CHECKPOINT_EVERY = 128
"""A request that goes ahead of others is simulated from the nearest earlier checkpoint."""
MEMO_SIZE = 4096
"""Entries kept by each of the estimator's look-up memos before it starts afresh."""
OVERDUE_SHARE = 0.5
"""A segment that has lasted longer than foretold is expected to last this share of the time
it has taken so far again (a robot held at a door, a slow lift, a chatty group): what is left
of it grows with the time it takes, never stays at a figure that has run out."""
GO_ON_PRIOR_N = 4
"""The prior share of visitors who answer "continue?" with yes (1.0) counts as this many
answers; the share learned from the tours then moves as a mean over the last ~20 answers."""
GO_ON_MIN_ALPHA = 0.05

Service = Literal["available", "busy", "held_up", "paused", "unavailable", "ended", "withdrawn"]
NO_PROMISE: frozenset[str] = frozenset({"unavailable", "held_up", "paused"})
"""Services under which a queued task is told no wait (nobody can say when a robot starts)."""


def _remember(memo: dict[int, Any], key: int, value: Any) -> None:
    """Keep ``value`` in a memo keyed by an object's id (the value holds the object, so the id
    stays its own while kept); a full memo starts afresh."""
    if len(memo) >= MEMO_SIZE:
        memo.clear()
    memo[key] = value


def speech_s(text: str) -> float:
    """Nominal seconds to say ``text`` (the same rule as the robot's timed speech)."""
    return 0.3 + len(text.split()) / WORDS_PER_SECOND if text.strip() else 0.0


@dataclass(slots=True)
class Segment:
    kind: Literal["move", "talk"]
    nominal_s: float
    index: int
    """1-based point of the tour this segment reaches (move) or explains (talk)."""


@dataclass(slots=True)
class Estimate:
    """What a visitor is told about one task."""

    service: Service
    wait_s: float | None
    """Until a robot starts on it (0 once assigned); None when no robot can serve."""
    arrival_s: float | None
    """Until the robot is at the first point; 0 once there; None when unknown."""
    remaining_s: float | None
    """Until the task ends (for a running task), None when unknown."""
    duration_s: float | None
    """The whole task from its first point (what the panel shows as the tour's length)."""

    def as_dict(self) -> dict[str, Any]:
        def r(v: float | None) -> float | None:
            return None if v is None else round(v, 1)

        return {
            "service": self.service,
            "eta_s": r(self.wait_s),
            "arrival_s": r(self.arrival_s),
            "remaining_s": r(self.remaining_s),
            "duration_s": r(self.duration_s),
        }


@dataclass(slots=True)
class _Factor:
    """A running ratio real/predicted: the first sample replaces the prior, later ones blend."""

    value: float = 1.0
    samples: int = 0

    def learn(self, real: float, predicted: float) -> None:
        if predicted <= 0.05 or real <= 0 or not math.isfinite(real):
            return
        ratio = min(max(real / predicted, 0.01), 100.0)
        alpha = max(0.3, 1.0 / (self.samples + 1))
        self.value = (1 - alpha) * self.value + alpha * ratio
        self.samples += 1


@dataclass(slots=True)
class _Share:
    """The share of "continue?" questions answered yes: a prior of 1.0 worth
    ``GO_ON_PRIOR_N`` answers, then a mean that follows the recent answers."""

    value: float = 1.0
    samples: int = 0

    def learn(self, yes: bool) -> None:
        alpha = max(GO_ON_MIN_ALPHA, 1.0 / (self.samples + 1 + GO_ON_PRIOR_N))
        self.value = (1 - alpha) * self.value + alpha * (1.0 if yes else 0.0)
        self.samples += 1


@dataclass(slots=True)
class _Rest:
    """The segments of a list of places after the leg to the first one, and their nominal
    seconds of legs and of explanations (a simulated task costs two multiplications)."""

    points: list[tuple[str, str | None]]
    speed: float
    segments: list[Segment]
    dwell: float = 1.0
    """Factor on the speech at each stop (a slower tour: guidebot/pace.py)."""
    move_s: float = 0.0
    talk_s: float = 0.0
    expected: tuple[float, float, float] = (1.0, 0.0, 0.0)
    """(share going on, nominal seconds of legs, of explanations) each weighted by the chance
    its visitors still follow the robot then: what a robot is expected to spend on it."""

    def __post_init__(self) -> None:
        self.move_s = sum(s.nominal_s for s in self.segments if s.kind == "move")
        self.talk_s = sum(s.nominal_s for s in self.segments if s.kind == "talk")
        self.expected = (1.0, self.move_s, self.talk_s)

    def expected_s(self, go_on: float) -> tuple[float, float]:
        """Nominal seconds of legs and explanations a robot is expected to spend on these
        places when each "continue?" is answered yes with chance ``go_on`` (cached per share)."""
        if self.expected[0] != go_on:
            move = talk = 0.0
            for seg in self.segments:
                w = go_on ** (seg.index - 1)
                if seg.kind == "move":
                    move += w * seg.nominal_s
                else:
                    talk += w * seg.nominal_s
            self.expected = (go_on, move, talk)
        return self.expected[1], self.expected[2]


@dataclass(slots=True)
class _Progress:
    """A task on its robot: its predicted segments and the last mark the robot reported."""

    segments: list[Segment]
    mark_at: float
    after: list[tuple[float, float]] = field(default_factory=list)
    """after[k]: nominal seconds of the legs and of the explanations in ``segments[k:]``, so
    what is left of a task costs two multiplications whatever its length (every task_event of
    a task on its robot carries it)."""
    done: int = 0
    """Segments finished (reported)."""
    index: int = 0
    total: int = 0
    poi: str | None = None
    name: str | None = None
    """The reported point's name in the task's language (from what its robot was given)."""
    stage: str = "assigned"
    learned: bool = False
    skipped: list[dict[str, Any]] = field(default_factory=list)
    """Points the tour skipped (closed off): index, poi, name, reason (what the visitor sees)."""
    first: int = 1
    """The tour's index of the first place in ``segments`` (a handed-over tour starts at the
    visitor's stop: backend/tasks/handover.py)."""
    asking: bool = False
    """A stop before the last was explained: the robot asks "continue?" and its visitors may
    end the tour there (learned by ``EtaEstimator.go_on``)."""
    going: bool = False
    """The visitors said yes after the stop explained: the robot leads them to the next."""

    def __post_init__(self) -> None:
        move = talk = 0.0
        after = [(0.0, 0.0)]
        for seg in reversed(self.segments):
            if seg.kind == "move":
                move += seg.nominal_s
            else:
                talk += seg.nominal_s
            after.append((move, talk))
        after.reverse()
        self.after = after


_Free = tuple[float, int, str, str | None, float]
"""A robot in the simulated line: when it is free, a tie-breaker, its name, where it is then and
its battery then (battery_forecast.py ``charge_first_s``: short of a task, it charges first)."""


@dataclass
class _Schedule:
    built_at: float
    waits: dict[str, tuple[float, float]] = field(default_factory=dict)
    """task id -> (wait, arrival) in real seconds from ``built_at``."""
    heap: list[_Free] = field(default_factory=list)
    """(free at, tie, robot, node, battery level) after the last scheduled task."""
    keys: list[tuple[int, int]] = field(default_factory=list)
    """(-priority, seq) of the tasks simulated, in queue order (where a new request goes)."""
    tasks: list[Task] = field(default_factory=list)
    checkpoints: list[list[_Free]] = field(default_factory=list)
    """checkpoints[c]: the heap before ``tasks[c * CHECKPOINT_EVERY]`` was simulated."""


def _point_name(task: Task, poi: str | None) -> str | None:
    """The name of point ``poi`` as the task's robot was given it (in the task's language),
    so a visitor is told the robot's real place even after the tour was edited."""
    points = task.assigned_params.get("points") if task.assigned_params else None
    for point in points if isinstance(points, list) else []:
        if isinstance(point, dict) and point.get("poi") == poi and point.get("name"):
            return str(point["name"])
    return None


class Fleet(Protocol):
    """What the estimator reads of the Task Manager (read only; TaskManager has it)."""

    @property
    def clock(self) -> Callable[[], float]: ...
    @property
    def site(self) -> Site: ...
    @property
    def graph(self) -> SiteGraph: ...
    @property
    def robots(self) -> Mapping[str, RobotInfo]: ...
    @property
    def tasks(self) -> Mapping[str, Task]: ...
    @property
    def queue(self) -> TaskQueue: ...
    def has_free_robot(self) -> bool: ...
    def target_of(self, kind: str, params: dict[str, Any]) -> str: ...
    def lift_wait_s(self, start: str | None, goal: str) -> float: ...


class EtaEstimator:
    """Owned by the Task Manager, which calls ``changed``, ``progress`` and ``ended``."""

    def __init__(self, manager: Fleet, *, refresh_s: float = 1.0) -> None:
        self.tm = manager
        self.refresh_s = refresh_s
        self.move = _Factor()
        self.talk = _Factor()
        self.go_on = _Share()
        """How often visitors answer "continue?" with yes: a tour ended early by its
        visitors frees its robot early, so the wait behind it counts each later stop by the
        chance it is still walked (the demo's visitors, and the paper's, leave mid-tour)."""
        self.charge_s = CHARGE_S
        self._running: dict[str, _Progress] = {}
        self._schedule: _Schedule | None = None
        self._places: dict[tuple[str, str, str | None, bool], list[tuple[str, str | None]]] = {}
        """(kind, tour or point, language, step-free) -> the places of a queued task (never
        changed by callers); for ``_places_of``, the site they were read from."""
        self._places_of: Site | None = None
        self._sent: dict[int, tuple[list[Any], list[tuple[str, str | None]]]] = {}
        """id of the points list a task's net was given -> (that list, its places)."""
        self._after_first: dict[int, _Rest] = {}
        """id of a list of places -> (the list, speed, the segments after the first leg):
        the same whichever robot starts them."""
        self._mean_speed: tuple[int, float] | None = None
        """(number of robots, their mean speed): for tasks not yet on a robot."""
        self.closed: Callable[[], Mapping[str, object]] | None = None
        """The nodes closed now (backend/closures): a queued tour's stops there, or cut off
        behind them (cutoff.py), are left out of its estimates (it will skip them); set by
        the closures component."""
        self.back_after: Callable[[str, float, Task], float | None] | None = None
        """Robots reserved for booked tours (backend/bookings/reserve.py): None if the robot
        may take the task when free in so many seconds, else when it is free after its booked
        tour; set by the bookings component."""
        self._cut_off = CutOff()
        self.paused = False
        """Staff paused the fleet (TaskManager.set_paused): no queued task starts until they
        resume, so none is told a wait (service ``paused``)."""

    # --- hooks from the Task Manager -----------------------------------------------------------
    def changed(self, task: Task, event: str) -> None:
        """A task changed: a request joining the queue is simulated into the schedule; any
        other change drops it (rebuilt when a wait is next asked)."""
        # A robot may start a task within its assignment (a VDA 5050 vehicle does), so the
        # first change seen may already be "running": track it then.
        started = task.state is TaskState.RUNNING and task.id not in self._running
        if task.robot is not None and (task.state is TaskState.ASSIGNED or started):
            robot = self.tm.robots.get(task.robot)
            start = robot.node if robot is not None else None
            self._running[task.id] = self._track(task, start)
        elif task.state is TaskState.QUEUED or task.final:
            self._stop(task)
        sched = self._schedule
        if sched is None or task.internal:
            return
        if event == "created" and task.state is TaskState.QUEUED and self._insert(sched, task):
            return
        self._schedule = None

    def progress(
        self, task: Task, index: int, stage: str, poi: str | None, reason: str = ""
    ) -> dict[str, Any]:
        """A robot reached (``arrived``), explained (``explained``) or skipped (``skipped``:
        closed off) point ``index`` of its task: learn the real time of the segment just ended
        and refine what is left (a skipped point's leg and talk are left out, not learned)."""
        run = self._running.get(task.id)
        if run is None:
            run = self._running[task.id] = self._track(task, None)
        now = self.tm.clock()
        at = index - run.first + 1  # the place in this robot's list
        if run.asking and index > run.index:
            run.asking = False  # the visitors went on after the question
            self.go_on.learn(True)
        run.going = False
        if stage == "skipped":
            name = _point_name(task, poi)
            run.skipped.append({"index": index, "poi": poi, "name": name, "reason": reason})
            run.done = max(run.done, min(2 * at, len(run.segments)))
            run.mark_at = now
            self._schedule = None
            return self.progress_view(task) or {}
        done = 2 * at - 1 if stage == "arrived" else 2 * at
        if done == run.done + 1 and done <= len(run.segments):
            seg = run.segments[done - 1]
            (self.move if seg.kind == "move" else self.talk).learn(now - run.mark_at, seg.nominal_s)
            run.learned = True
        run.done = max(run.done, min(done, len(run.segments)))
        run.mark_at = now
        run.index, run.stage, run.poi = index, stage, poi
        run.name = _point_name(task, poi)
        run.asking = stage == "explained" and task.kind == "tour" and index < run.total
        self._schedule = None
        return self.progress_view(task) or {}

    def seen_at(self, task: Task, poi: str) -> None:
        """Its robot says it showed ``poi`` (robot_state ``poi``): the stop the visitor is at,
        kept when this process has no report of it (a restarted server: a handover then still
        goes on from there, backend/tasks/handover.py). Nothing is learned from it."""
        run = self._running.get(task.id)
        if run is not None and run.index > 0:
            return
        tour = self.tm.site.tour(str(task.params.get("tour")))
        if tour is None or poi not in tour.points:
            return
        if run is None:
            run = self._running[task.id] = self._track(task, None)
        run.index, run.total, run.stage, run.poi = (
            tour.points.index(poi) + 1,
            len(tour.points),
            "arrived",
            poi,
        )
        run.name = _point_name(task, poi)

    def went_on(self, task: Task) -> bool:
        """A tour's robot is on its way again after a stop explained (its ``robot_state``
        navigation): the visitors answered yes and it leads them to the next stop. True if
        news (once per stop)."""
        run = self._running.get(task.id)
        if run is None or not run.asking:
            return False
        run.asking, run.going = False, True
        self.go_on.learn(True)
        self._schedule = None
        return True

    def point_shown(self, task: Task, poi: str) -> bool:
        """A visit's robot says it shows its point (robot_state ``poi``; a visit sends no
        tour_progress): it arrived, as a tour's stop is reported (once). True if news."""
        if task.kind != "go_to_poi" or poi != task.params.get("poi"):
            return False
        run = self._running.get(task.id)
        if run is not None and run.index > 0:
            return False
        self.progress(task, 1, "arrived", poi)
        return True

    def ended(self, task: Task, took_s: float | None) -> None:
        """Learn from a task that ended done: the whole, when no segment was reported."""
        run = self._stop(task)
        if task.kind == "charge" and took_s:
            self.charge_s = took_s
            return
        if run is None or run.learned or not took_s:
            return
        moves, talks = run.after[0]
        predicted = moves * self.move.value + talks * self.talk.value
        if predicted > 0:
            scale = took_s / predicted  # spread the surprise over both kinds of segment
            self.move.learn(moves * self.move.value * scale, moves)
            self.talk.learn(talks * self.talk.value * scale, talks)

    # --- what the visitor sees ----------------------------------------------------------------
    def service(self) -> Service:
        """available: a robot could start now; busy: all working robots are busy;
        held_up: every working robot is held up (a jam: nobody can say when one is free);
        paused: staff paused the fleet (nothing starts until they resume);
        unavailable: no robot is in service (offline or in fault)."""
        if self.paused:
            return "paused"
        working = [r for r in self.tm.robots.values() if r.online and not r.fault]
        if not working:
            return "unavailable"
        if all(r.held_up for r in working):
            return "held_up"
        if self.tm.has_free_robot():
            return "available"
        return "busy"

    def estimate(self, task: Task) -> Estimate:
        if task.final:
            gone = task.state is TaskState.CANCELLED and "the site changed" in task.reason
            return Estimate("withdrawn" if gone else "ended", None, None, 0.0, None)
        if task.state is not TaskState.QUEUED:
            run = self._running.get(task.id)
            if run is None:
                return Estimate("available", 0.0, None, None, None)
            duration = self._real_after(run, 1)
            robot = self.tm.robots.get(task.robot or "")
            if robot is not None and robot.held_up:  # a jam: no promise of when
                return Estimate("held_up", 0.0, None if run.done == 0 else 0.0, None, duration)
            remaining = self._remaining(run)
            first: float | None = 0.0
            if run.done == 0:
                # Later than foretold on its way to the first stop: on its way, no figure
                # (one that has run out is no promise: docs/visitor.md, "The wait").
                first = None if self._overdue(run) else self._remaining(run, upto=1)
            return Estimate("available", 0.0, first, remaining, duration)
        duration = self._real(self.segments(task, None)[1:])
        service = self.service()
        if service in NO_PROMISE:
            return Estimate(service, None, None, None, duration)
        sched = self._current()
        found = sched.waits.get(task.id)
        if found is None:
            return Estimate(service, None, None, None, duration)
        return self._told(sched, found[0], found[1], duration)

    def preview(self, kind: str, params: dict[str, Any]) -> Estimate:
        """What a new request would be told now (the panel shows it before the visitor asks)."""
        probe = Task(id="~preview", kind=kind, params=params, priority=5, requester="", seq=0)
        duration = self._real(self.segments(probe, None)[1:])
        service = self.service()
        if service in NO_PROMISE:
            return Estimate(service, None, None, None, duration)
        sched = self._current()
        heap = list(sched.heap)
        wait, arrival, _ = self._place(heap, probe)
        return self._told(sched, wait, arrival, duration)

    def _told(
        self, sched: _Schedule, wait: float, arrival: float, duration: float | None
    ) -> Estimate:
        if not math.isfinite(wait):
            jam = any(r.held_up for r in self._pool())
            return Estimate("held_up" if jam else "busy", None, None, None, duration)
        age = self.tm.clock() - sched.built_at
        wait, arrival = max(0.0, wait - age), max(0.0, arrival - age)
        return Estimate("available" if wait <= 0 else "busy", wait, arrival, None, duration)

    def next_free_s(self) -> float | None:
        """Seconds until the first robot is free after the whole line (None: not known)."""
        if self.service() in NO_PROMISE:
            return None
        sched = self._current()
        if not sched.heap or not math.isfinite(sched.heap[0][0]):
            return None
        return round(max(0.0, sched.heap[0][0] - (self.tm.clock() - sched.built_at)), 1)

    def _stop(self, task: Task) -> _Progress | None:
        """Stop following a task on its robot; a tour that ended keeps where it got to, a
        visit to one point that its robot had reached keeps that (the visit happened)."""
        run = self._running.pop(task.id, None)
        if run is not None and task.final:
            if task.kind == "tour" or (task.kind == "go_to_poi" and run.index > 0):
                task.final_progress = self._view(run)
            if run.asking and task.state is TaskState.DONE:
                self.go_on.learn(False)  # its visitors ended the tour at "continue?"
        return run

    def progress_view(self, task: Task) -> dict[str, Any] | None:
        """A tour's progress on its robot; once it ended, where it got to (None: it never
        reached its robot, or a restart forgot it). A visit to one point: once its robot is
        there (``point_shown``), index 1 of 1 arrived."""
        if task.kind == "go_to_poi":
            run = self._running.get(task.id)
            if run is None:
                return task.final_progress if task.final else None
            return self._view(run) if run.index > 0 else None
        if task.kind != "tour":
            return None
        run = self._running.get(task.id)
        if run is None:
            return task.final_progress if task.final else None
        return self._view(run)

    @staticmethod
    def _view(run: _Progress) -> dict[str, Any]:
        view = {
            "index": run.index,
            "total": run.total,
            "poi": run.poi,
            "name": run.name,
            "stage": run.stage,
            "skipped": list(run.skipped),
        }
        if run.going:  # its visitors said yes: the robot leads them to the next stop
            view["going"] = True
        return view

    # --- the model ------------------------------------------------------------------------------
    def segments(self, task: Task, start: str | None) -> list[Segment]:
        """Nominal segments of ``task`` when its robot starts at node ``start`` (unknown:
        ``UNKNOWN_TRAVEL_M`` to the first point)."""
        return self._segments(
            self._points(task), start, self._speed(task.robot), pace_of(task.params)
        )

    def first_node(self, task: Task) -> str | None:
        """Where a task given to a robot now starts: a handed-over tour's visitor's stop (its
        points from there on), else None (its kind's target)."""
        if not task.resume_from:
            return None
        points = self._points(task)
        return points[0][0] if points else None

    def task_s(self, task: Task, start: str | None) -> float:
        """Real seconds ``task`` would take a robot at ``start`` (battery check: charging.py)."""
        return self._real(self.segments(task, start))

    def _track(self, task: Task, start: str | None) -> _Progress:
        """Start following a task on its robot (its places are looked up once)."""
        points = self._points(task)
        segments = self._segments(points, start, self._speed(task.robot), pace_of(task.params))
        total = sum(1 for _, text in points if text is not None)
        first = 1
        sent = task.assigned_params.get("points") if task.assigned_params else None
        if isinstance(sent, list) and sent and isinstance(sent[0], dict):
            first = int(sent[0].get("index") or 1)
            total = int(sent[0].get("total") or total)
        run = _Progress(segments, self.tm.clock(), total=total, first=first)
        run.skipped = list(task.assigned_params.get("skipped") or [])  # first stops, steps only
        return run

    def _segments(
        self, points: list[tuple[str, str | None]], start: str | None, speed: float, pace: Pace
    ) -> list[Segment]:
        """The leg to the first place at the robot's speed (nobody follows it yet), the rest
        at the task's pace."""
        if not points:
            return []
        lift = self.tm.lift_wait_s(start, points[0][0])  # its turn at the lift (lifts.py)
        first = Segment("move", self._metres(start, points[0][0]) / speed + lift, 1)
        return [first, *self._rest(points, speed * pace.speed, pace.dwell).segments]

    def _rest(
        self, points: list[tuple[str, str | None]], speed: float, dwell: float = 1.0
    ) -> _Rest:
        """What follows the leg to the first place (the same whichever robot starts there)."""
        found = self._after_first.get(id(points))
        if (
            found is None
            or found.points is not points
            or found.speed != speed
            or found.dwell != dwell
        ):
            segments = self._segments_after_first(points, speed, dwell)
            found = _Rest(points, speed, segments, dwell)
            _remember(self._after_first, id(points), found)
        return found

    def _segments_after_first(
        self, points: list[tuple[str, str | None]], speed: float, dwell: float
    ) -> list[Segment]:
        out: list[Segment] = []
        here = points[0][0]
        for i, (node, text) in enumerate(points, start=1):
            if i > 1:
                metres = self._metres(here, node)
                out.append(Segment("move", metres / speed + QUESTION_S, i))
            if text is not None:
                out.append(Segment("talk", FACE_AND_REST_S + speech_s(text) * dwell, i))
            here = node
        return out

    def _points(self, task: Task) -> list[tuple[str, str | None]]:
        """(node, spoken text or None) of each place the task visits (a queued task: not
        those closed now or cut off behind a closure, which its tour will skip)."""
        places = self._all_points(task)
        closed = self.closed() if self.closed is not None else None
        if closed and task.state is TaskState.QUEUED:
            cut = self._cut_off.cut_off(self.tm.site, self.tm.graph, closed.keys())
            return [place for place in places if place[0] not in closed and place[0] not in cut]
        return places

    def _all_points(self, task: Task) -> list[tuple[str, str | None]]:
        sent = task.assigned_params.get("points") if task.assigned_params else None
        if isinstance(sent, list) and sent:
            known = self._sent.get(id(sent))
            if known is not None and known[0] is sent:
                return known[1]
            places: list[tuple[str, str | None]] = [
                (str(p.get("node")), str(p.get("text") or "")) for p in sent
            ]
            _remember(self._sent, id(sent), (sent, places))
            return places
        site, p = self.tm.site, task.params
        lang = p.get("lang") if isinstance(p.get("lang"), str) else None
        if task.kind in ("tour", "go_to_poi"):
            if self._places_of is not site:
                self._places.clear()
                self._places_of = site
            ref = str(p.get("tour" if task.kind == "tour" else "poi"))
            key = (task.kind, ref, lang, p.get("step_free") is True)
            found = self._places.get(key)
            if found is None:
                found = self._places[key] = self._site_points(site, *key[:3])
                if key[3] and task.kind == "tour" and (tour := site.tour(ref)) is not None:
                    # a step-free tour starts at its first stop without steps (access.py)
                    del found[: len(first_stops_skipped(site, self.tm.graph, tour))]
            return found
        try:
            return [(self.tm.target_of(task.kind, p), None)]
        except ValueError:
            return []

    @staticmethod
    def _site_points(
        site: Site, kind: str, ref: str, lang: str | None
    ) -> list[tuple[str, str | None]]:
        if kind == "tour":
            tour = site.tour(ref)
            pois = [site.poi(i) for i in (tour.points if tour else [])]
            return [(q.node, poi_texts(site, q, lang)["text"]) for q in pois if q is not None]
        poi = site.poi(ref)
        return [(poi.node, poi_texts(site, poi, lang)["text"])] if poi else []

    def site_changed(self) -> None:
        """The site was replaced or edited: forget the places looked up in it."""
        self._places.clear()
        self._places_of = None
        self._sent.clear()
        self._after_first.clear()

    def _metres(self, start: str | None, goal: str) -> float:
        if start is None or start not in self.tm.graph or goal not in self.tm.graph:
            return UNKNOWN_TRAVEL_M if start != goal else 0.0
        found = self.tm.graph.distances_to(goal).get(start)
        return UNKNOWN_TRAVEL_M if found is None or math.isinf(found) else found

    def _speed(self, robot: str | None) -> float:
        info = self.tm.robots.get(robot) if robot else None
        if info is not None:
            return info.config.max_speed_mps
        robots = self.tm.robots
        if self._mean_speed is None or self._mean_speed[0] != len(robots):
            speeds = [r.config.max_speed_mps for r in robots.values()]
            self._mean_speed = (len(robots), sum(speeds) / len(speeds) if speeds else 0.7)
        return self._mean_speed[1]

    def _real(self, segments: list[Segment]) -> float:
        move, talk = self.move.value, self.talk.value
        return sum(s.nominal_s * (move if s.kind == "move" else talk) for s in segments)

    def _expected(self, segments: list[Segment]) -> float:
        """Real seconds a robot is expected to spend on ``segments`` (a task's whole list):
        each stop counted by the chance its visitors still go on then."""
        move, talk, go_on = self.move.value, self.talk.value, self.go_on.value
        return sum(
            s.nominal_s * (move if s.kind == "move" else talk) * go_on ** max(0, s.index - 1)
            for s in segments
        )

    def _real_after(self, run: _Progress, k: int) -> float:
        """Real seconds of ``run.segments[k:]``."""
        move, talk = run.after[min(k, len(run.segments))]
        return move * self.move.value + talk * self.talk.value

    def _seg_real(self, seg: Segment) -> float:
        return seg.nominal_s * (self.move.value if seg.kind == "move" else self.talk.value)

    def _overdue(self, run: _Progress) -> bool:
        """The segment in progress has taken longer than foretold."""
        if run.done >= len(run.segments):
            return False
        return self.tm.clock() - run.mark_at > self._seg_real(run.segments[run.done])

    def _remaining(self, run: _Progress, upto: int | None = None) -> float:
        """Real seconds left of a running task (or of its first ``upto`` segments). The
        segment in progress counts down from the last report; once it has taken longer than
        foretold it is expected to take ``OVERDUE_SHARE`` of its time so far again (a figure
        that grows while the robot is late, never one that ran out). The whole task counts
        each later stop by the chance its visitors still go on then (``go_on``)."""
        end = len(run.segments) if upto is None else min(upto, len(run.segments))
        if run.done >= end:
            return 0.0
        elapsed = self.tm.clock() - run.mark_at
        seg = run.segments[run.done]
        current = max(self._seg_real(seg) - elapsed, OVERDUE_SHARE * elapsed)
        go_on = self.go_on.value
        if upto is not None or go_on >= 1.0:
            rest = self._real_after(run, run.done + 1) - self._real_after(run, end)
            return current + rest
        # Each "continue?" still to come may end the tour: an open one (the stop explained,
        # the question asked) weighs even the segment in progress.
        asked = seg.index - (1 if run.asking else 0)
        move = talk = 0.0
        for later in run.segments[run.done + 1 : end]:
            w = go_on ** (later.index - asked)
            if later.kind == "move":
                move += w * later.nominal_s
            else:
                talk += w * later.nominal_s
        now = go_on ** (seg.index - asked)
        return now * current + move * self.move.value + talk * self.talk.value

    # --- the queue simulation -------------------------------------------------------------------
    def _current(self) -> _Schedule:
        sched = self._schedule
        if sched is None or self.tm.clock() - sched.built_at > self.refresh_s:
            sched = self._schedule = self._build()
        return sched

    def _build(self) -> _Schedule:
        sched = _Schedule(built_at=self.tm.clock())
        for tie, robot in enumerate(self._pool()):
            free_at, node = self._free(robot)
            sched.heap.append((free_at, tie, robot.name, node, self._level(robot, free_at)))
        heapq.heapify(sched.heap)
        for task in self.tm.queue.ordered():
            if not task.internal:
                sched.keys.append((-task.priority, task.seq))
                sched.tasks.append(task)
        self._simulate(sched, 0)
        return sched

    def _simulate(self, sched: _Schedule, start: int) -> None:
        """Simulate ``sched.tasks[start:]`` from the checkpoint at ``start`` (or, past the
        last task simulated, from the final heap), keeping the waits, the checkpoints and the
        final heap."""
        c, off = divmod(start, CHECKPOINT_EVERY)
        if off == 0 and c < len(sched.checkpoints):  # else: go on from the final heap
            sched.heap = list(sched.checkpoints[c])
            del sched.checkpoints[c:]
        heap = sched.heap
        for i in range(start, len(sched.tasks)):
            if i % CHECKPOINT_EVERY == 0:
                sched.checkpoints.append(list(heap))
            task = sched.tasks[i]
            wait, arrival, _ = self._place(heap, task)
            sched.waits[task.id] = (wait, arrival)

    def _insert(self, sched: _Schedule, task: Task) -> bool:
        """A request joined the queue: at the tail it extends the schedule; ahead of others
        the simulation runs again from the last checkpoint before its place (the tasks behind
        it wait longer), not from the start."""
        if self.tm.queue.position(task) is None:
            return False
        key = (-task.priority, task.seq)
        at = bisect.bisect_right(sched.keys, key)
        sched.keys.insert(at, key)
        sched.tasks.insert(at, task)
        self._simulate(sched, at if at == len(sched.tasks) - 1 else at - at % CHECKPOINT_EVERY)
        return True

    def _pool(self) -> list[RobotInfo]:
        working = [r for r in self.tm.robots.values() if r.online and not r.fault]
        fit = [r for r in working if not r.needs_charge and r.battery > r.config.battery_low]
        return fit or working

    def _free(self, robot: RobotInfo) -> tuple[float, str | None]:
        """When (real seconds from now) and where ``robot`` is free for the next task."""
        if robot.held_up:
            return math.inf, robot.node  # a jam: nobody can say when
        current = self.tm.tasks.get(robot.current) if robot.current else None
        free_at, node = 0.0, robot.node
        if current is not None and not current.internal and not current.final:
            run = self._running.get(current.id)
            if run is not None:
                free_at = self._remaining(run)
            else:
                free_at = self._expected(self.segments(current, robot.node))
            points = self._points(current)
            node = points[-1][0] if points else node
        if robot.needs_charge or robot.battery <= robot.config.battery_low:
            free_at += self.charge_s
        return free_at, node

    def _level(self, robot: RobotInfo, free_at: float) -> float:
        """Its battery when it is free: charged after a charge it is due, else what its
        current task leaves it at its learned drain."""
        if robot.needs_charge or robot.battery <= robot.config.battery_low:
            return CHARGED
        drain = robot.drain_per_s
        if drain is None or not math.isfinite(free_at):
            return robot.battery
        return robot.battery - drain * free_at

    def _first_free(self, heap: list[_Free], task: Task) -> _Free:
        """The robot free first; with robots reserved for booked tours (``back_after``,
        backend/bookings/reserve.py), the first whose booking leaves time for ``task``: a
        reserved one counts from when its booked tour ends."""
        entry = heapq.heappop(heap)
        back_after = self.back_after
        if back_after is None:
            return entry
        later = []
        while (back := back_after(entry[2], entry[0], task)) is not None:
            later.append((back, *entry[1:]))
            if not heap:
                break
            entry = heapq.heappop(heap)
        else:
            for e in later:
                heapq.heappush(heap, e)
            return entry
        for e in later:  # every robot is reserved: the one back first
            heapq.heappush(heap, e)
        return heapq.heappop(heap)

    def _place(self, heap: list[_Free], task: Task) -> tuple[float, float, str | None]:
        """Give ``task`` to the robot free first (its pinned one if any); returns wait,
        arrival and the robot, and books the robot until the task ends. A robot whose battery
        would not last the task charges first (the Task Manager sends it to a station): it is
        free that much later, and another robot may be free before it."""
        if not heap:
            return math.inf, math.inf, None
        if task.pinned_robot is not None:
            entry = next((e for e in heap if e[2] == task.pinned_robot), None)
            if entry is None:
                return math.inf, math.inf, None
            heap.remove(entry)
            heapq.heapify(heap)
        else:
            entry = self._first_free(heap, task)
        points = self._points(task)
        if not points:
            heapq.heappush(heap, entry)
            return entry[0], entry[0], entry[2]
        speed = self._speed(task.robot)
        pace = pace_of(task.params)
        rest = self._rest(points, speed * pace.speed, pace.dwell)
        move, talk = self.move.value, self.talk.value
        rest_move, rest_talk = rest.expected_s(self.go_on.value)
        while True:
            free_at, tie, name, node, level = entry
            first = self._metres(node, points[0][0]) / speed * move
            first += self.tm.lift_wait_s(node, points[0][0]) * move
            took = first + rest_move * move + rest_talk * talk
            robot = self.tm.robots.get(name)
            if robot is None or robot.drain_per_s is None:
                break
            charge_s = charge_first_s(robot, level, took, self.tm.robots.values())
            if charge_s <= 0:
                level -= robot.drain_per_s * took
                break
            # Charged just enough for it: the same robot found again takes it at once.
            level = finish_floor(robot) + robot.drain_per_s * took
            entry = (free_at + charge_s, tie, name, node, level)
            if task.pinned_robot is None:
                heapq.heappush(heap, entry)
                entry = self._first_free(heap, task)
        heapq.heappush(heap, (free_at + took, tie, name, points[-1][0], level))
        return free_at, free_at + first, name
