"""Live waits for visitors: a task's place in line, its wait and its robot's arrival change
without the task changing (a task ahead left the line, a robot is slower than told, a jam), and
the wait a new request would get changes with the fleet. The Task Manager's clock (its
watchdog tick) calls ``check``, which publishes a ``task_event`` for each visitor task whose
news differs from what was last told, and ``visitor_service`` when the overall service or the
next free robot's wait does (docs/visitor.md, "Live waits").

What was told counts down: a page shows a told wait minus the time since it was told, so a wait
is told again only when the estimate drifts from that countdown by more than ``DRIFT_MIN_S``
or ``DRIFT_SHARE`` of it. Only the first ``LIVE_QUEUE`` queued tasks are followed (a longer
line is followed as it moves up), and tasks on a robot until their first stop (then their
visitor is with the robot). A check costs a simulation of the line when anything changed: the
next one waits at least ``COST_FACTOR`` times as long as it took, so a huge line and fleet
(10 000 tasks, 1 000 robots) spend at most ~5 % of the loop on it.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from backend.tasks.book import TaskBook
from backend.tasks.model import Task, TaskState
from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.site import SiteLoaded
from guidebot.payloads.tasks import TaskEvent, VisitorService

if TYPE_CHECKING:
    from backend.tasks.eta import EtaEstimator

__all__ = ["DRIFT_MIN_S", "DRIFT_SHARE", "LIVE_QUEUE", "QueueNews"]

LIVE_QUEUE = 100
"""Queued tasks followed, from the head of the line."""
COST_FACTOR = 20.0
"""The next check waits at least this many times what the last one took."""
DRIFT_MIN_S = 10.0
DRIFT_SHARE = 0.15
"""A wait is told again when it drifts from the told countdown by more than this share of it
(and at least ``DRIFT_MIN_S``)."""
BUSY_EVERY_S = 1.0
"""After a change (a task, a robot held up or free again), a check at most this often."""
QUIET_EVERY_S = 5.0
"""Without a change, a check this often (robots slower or faster than told)."""


@dataclass(slots=True)
class _Told:
    """What a visitor was last told about a task (or the overall service), and when."""

    position: int | None
    service: str | None
    eta_s: float | None
    arrival_s: float | None
    at: float


def _drifted(told: float | None, told_at: float, now_value: float | None, now: float) -> bool:
    if told is None or now_value is None:
        return (told is None) != (now_value is None)
    countdown = max(0.0, told - (now - told_at))
    return abs(now_value - countdown) > max(DRIFT_MIN_S, DRIFT_SHARE * now_value)


class Newsroom(Protocol):
    """What the news reads of the Task Manager (it writes nothing there)."""

    book: TaskBook
    clock: Callable[[], float]
    endpoint: BusEndpoint
    estimator: EtaEstimator

    def event(self, task: Task) -> TaskEvent: ...
    def queue_position(self, task: Task) -> int | None: ...


class QueueNews:
    """Owned by the Task Manager: ``told`` after every task_event it publishes, ``changed``
    on news that may move waits, ``check`` on its clock."""

    def __init__(self, manager: Newsroom) -> None:
        self.tm = manager
        self._told: dict[str, _Told] = {}
        self._overall: _Told | None = None
        self._dirty = True
        self._checked_at = float("-inf")
        self._pause_s = 0.0
        """At least this long between checks: COST_FACTOR times what the last one took."""

    def changed(self) -> None:
        """Something that may move waits happened: check on the next tick."""
        self._dirty = True

    def told(self, event: TaskEvent) -> None:
        """A task_event went out: its waits are what the visitor was told."""
        self._dirty = True
        if event.state in ("done", "failed", "cancelled"):
            self._told.pop(event.task_id, None)
            return
        self._told[event.task_id] = _Told(
            event.queue_position, event.service, event.eta_s, event.arrival_s, self.tm.clock()
        )

    def check(self) -> int:
        """Tell what drifted; returns how many task_events were published."""
        tm = self.tm
        now = tm.clock()
        every = BUSY_EVERY_S if self._dirty else QUIET_EVERY_S
        if now - self._checked_at < max(every, self._pause_s):
            return 0
        self._checked_at = now
        self._dirty = False
        t0 = time.perf_counter()
        try:
            return self._check(now)
        finally:
            self._pause_s = COST_FACTOR * (time.perf_counter() - t0)

    def _check(self, now: float) -> int:
        tm = self.tm
        self._service(now)
        sent = 0
        for task in itertools.chain(
            itertools.islice(tm.book.queue.head(), LIVE_QUEUE), self._on_robots()
        ):
            if task.internal:
                continue
            if self._news(task, now):
                event = tm.event(task)
                tm.endpoint.publish(event)
                self.told(event)
                self._dirty = False
                sent += 1
        tasks = tm.book.tasks
        for gone in [i for i in self._told if (t := tasks.get(i)) is None or t.final]:
            del self._told[gone]
        return sent

    def _on_robots(self) -> list[Task]:
        """Tasks on a robot that has not reached their first stop (arrival still counts)."""
        tm = self.tm
        book = tm.book
        on = (book.tasks.get(r.current) for r in book.robots.values() if r.current is not None)
        return [
            t
            for t in on
            if t is not None
            and t.state is not TaskState.QUEUED
            and not t.internal
            and not (tm.estimator.progress_view(t) or {}).get("index")
        ]

    def _news(self, task: Task, now: float) -> bool:
        told = self._told.get(task.id)
        if told is None:  # never told since this server started (restored): tell it
            return True
        estimate = self.tm.estimator.estimate(task).as_dict()
        fresh = _Told(
            self.tm.queue_position(task),
            estimate["service"],
            estimate["eta_s"],
            estimate["arrival_s"],
            now,
        )
        return (
            told.position != fresh.position
            or told.service != fresh.service
            or _drifted(told.eta_s, told.at, fresh.eta_s, now)
            or _drifted(told.arrival_s, told.at, fresh.arrival_s, now)
        )

    def robot_connected(self, message: Message, loaded: SiteLoaded) -> None:
        """A robot says which site it runs, as it does on every connect once its link is up
        and subscribed: its touch screen is told the service as it stands (staff may have
        paused the fleet meanwhile; later changes come as broadcasts). An answer to the
        robot's own message, not to robot_connected: that would reach the robot in the hub's
        first frame with its welcome, which its hub client takes for no welcome at all."""
        robot = loaded.robot or message.source
        if not robot:
            return
        estimator = self.tm.estimator
        news = VisitorService(service=estimator.service(), eta_s=estimator.next_free_s())
        self.tm.endpoint.publish(news, destination=robot)

    def _service(self, now: float) -> None:
        """``visitor_service`` when the overall service or the next free robot's wait moved
        (the panels read their menu again)."""
        estimator = self.tm.estimator
        fresh = _Told(None, estimator.service(), estimator.next_free_s(), None, now)
        told = self._overall
        if told is not None and not (
            told.service != fresh.service or _drifted(told.eta_s, told.at, fresh.eta_s, now)
        ):
            return
        self._overall = fresh
        # The first too: a change (staff's pause) may come before the first check, and pages
        # and touch screens that read the service earlier would never hear of it.
        self.tm.endpoint.publish(VisitorService(service=estimator.service(), eta_s=fresh.eta_s))
