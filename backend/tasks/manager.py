"""The Task Manager: the queue, assignment by path cost/battery/availability, and the task
life cycle (docs/server.md). The entry point: requests, staff actions and assignment live
here; its parts each handle one kind of news and call back into it:

- backend/tasks/requests.py: ``task_request`` over the hub (repeats, refusals, answers);
- backend/tasks/reports.py: a robot's reports on its task (started, ended, tour progress);
- backend/tasks/presence.py: ``robot_state``, link loss, reconciliation after a restart;
- backend/tasks/battery.py: ``battery_low`` and ``battery_panic``;
- backend/tasks/watchdog.py: silent robots, lost robots' tasks, tasks nobody started;
- backend/tasks/book.py: the state they share (tasks, robots, queue, the marks between them),
  changed only through its operations;
- backend/tasks/choice.py and targets.py: pure functions (which robot, where idle robots go,
  where a task starts, what its net is given).

Handlers run inline on the bus and never block: persistence goes through a write-behind
``TaskStore``.
"""

from __future__ import annotations

import itertools
import math
import time
import uuid
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from backend.alerts import AlertStore
from backend.tasks.battery import BatteryAlarms
from backend.tasks.battery_forecast import charge_first_s
from backend.tasks.blocked import BlockedErrands
from backend.tasks.book import TaskBook
from backend.tasks.charging import can_finish, station_for
from backend.tasks.choice import available, choose_robot, idle_errands
from backend.tasks.eta import EtaEstimator
from backend.tasks.handover import note_break, resumed_points
from backend.tasks.lifts import LiftWait
from backend.tasks.model import (
    Held,
    InvalidTask,
    QueueFull,
    Task,
    TaskError,
    TaskFinished,
    TaskNotFound,
    TaskState,
)
from backend.tasks.news import QueueNews
from backend.tasks.params import validate_params
from backend.tasks.presence import Presence
from backend.tasks.queue import TaskQueue
from backend.tasks.reports import TaskReports
from backend.tasks.requests import HubRequests
from backend.tasks.robots import RobotInfo
from backend.tasks.targets import net_params, target_node
from backend.tasks.trouble import TroubleWaits
from backend.tasks.watchdog import Watchdog
from guidebot.bus import BusEndpoint
from guidebot.delivery import courier_for, listen
from guidebot.messages import Message, make_message
from guidebot.payloads.robot import BatteryAlarm, RobotState
from guidebot.payloads.site import SiteLoaded
from guidebot.payloads.tasks import (
    RobotLink,
    RobotService,
    TaskAssigned,
    TaskCancel,
    TaskEnded,
    TaskEvent,
    TaskStarted,
    TourProgress,
)
from guidebot.service import Service
from guidebot.site.graph import SiteGraph
from guidebot.site.i18n import site_languages
from guidebot.site.schema import Site
from guidebot.task_kinds import KINDS, VISITOR_KINDS

__all__ = ["TaskManager", "TaskStore"]

NETS = {kind: spec.net for kind, spec in KINDS.items()}
CHARGE_UNREACHABLE = "charge_unreachable"
"""The alert kind (subject: the robot) of a robot whose way to a charger is blocked."""
SHORT_LOOK = 20
"""An idle robot whose battery would not last this many queued tasks it may take in a row is
short of the queue's work (``_work_for``): it charges."""


class TaskStore(Protocol):
    """Where tasks and their history go (backend.db.store.DbTaskStore); must not block."""

    def record(
        self,
        task: Task,
        event: str,
        detail: dict[str, Any] | None = None,
        at: float | None = None,
    ) -> None: ...

    def record_service(self, robot: str, out_of_service: bool, by: str = "") -> None: ...


class TaskHold(Protocol):
    """What the fire alarm holds (backend.emergency.EmergencyService)."""

    def refusal(self, lang: str | None) -> str | None: ...
    def holds(self, robot: RobotInfo) -> bool: ...


class TaskReservations(Protocol):
    """Robots reserved for booked tours (backend.bookings.reserve.Reservations)."""

    def keeps(self, robot: RobotInfo, task: Task) -> bool: ...
    def parks(self, robot: RobotInfo) -> bool: ...


class TaskManager(Service):
    """One per server. ``graph`` is shared with the Traffic Manager (same site version)."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        site: Site,
        *,
        graph: SiteGraph | None = None,
        store: TaskStore | None = None,
        robot_timeout_s: float = 10.0,
        lost_grace_s: float = 30.0,
        start_timeout_s: float = 30.0,
        report_grace_s: float = 0.0,
        tick_s: float | None = 0.5,
        max_queued: int = 100_000,
        clock: Callable[[], float] = time.monotonic,
        alerts: AlertStore | None = None,
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.store = store
        self.robot_timeout_s = robot_timeout_s
        self.lost_grace_s = lost_grace_s
        self.start_timeout_s = start_timeout_s
        self.report_grace_s = report_grace_s
        """How long a task restored by a new leader that its robot no longer names waits for the
        robot's task_ended before it goes back to the queue: one sent while no process decided
        comes again on the robot link's back-off (at most 8 s, +-20 %), possibly after the
        robot_state (docs/server.md, "After a restart"). 0 for one process: its robots all
        reconnect to a restarted server and send what was not acknowledged before their state."""
        self.tick_s = tick_s
        self.clock = clock
        self.book = TaskBook(max_queued)
        """Tasks, robots, the queue and the marks between them (backend/tasks/book.py)."""
        # The book's own collections, to read (plain attributes: read in every estimate).
        self.tasks: Mapping[str, Task] = self.book.tasks
        self.robots: Mapping[str, RobotInfo] = self.book.robots
        self.queue: TaskQueue = self.book.queue
        self._seq = itertools.count(1)
        self._dispatching = False
        self.paused = False
        """Staff paused the fleet (set_paused): nothing is dispatched until they resume."""
        self._dispatch_again = False
        self.assign_times_ms: list[float] | None = None
        self._net_params: dict[tuple[str, tuple[tuple[str, Any], ...]], dict[str, Any]] = {}
        """(kind, params) -> what its net is given on this site (shared, never changed)."""
        self.lifts = LiftWait()
        """The lifts' queue (set ``lifts.queue`` to read the Traffic Manager's) and turns."""
        self._lift_queued: tuple[float, int] | None = None
        self.site = site
        self.graph = graph or SiteGraph(site)
        self.estimator = EtaEstimator(self)
        """Waits, arrivals and durations told to visitors (backend/tasks/eta.py)."""
        self.news = QueueNews(self)
        """Waits told again as they change without a task change (backend/tasks/news.py)."""
        self.courier = courier_for(endpoint)
        """task_assigned and task_cancel: sent again until the robot acknowledges them."""
        self.hub_requests = HubRequests(self)
        self.reports = TaskReports(self)
        self.presence = Presence(self, self.reports)
        self.battery = BatteryAlarms(self)
        self.watchdog = Watchdog(self, self.presence)
        self.trouble = TroubleWaits()
        """Visitors' tasks cut off only by trouble, queued until it lifts (trouble.py)."""
        self.blocked = BlockedErrands()
        """Idle robots' errands that failed, not made again until something changes
        (blocked.py)."""
        self.alerts = alerts
        """Staff alerts (backend/alerts.py): a robot that cannot reach a charger."""
        self.hold: TaskHold | None = None
        """The fire alarm's hold (backend.emergency): no task for the robots it holds, no
        new request while it lasts."""
        self.reservations: TaskReservations | None = None
        """Booked tours' robots (backend/bookings/reserve.py): a reserved robot takes no task
        that would make it late, and waits at its meeting point."""
        self.load_site(site, self.graph)

    # --- life cycle ----------------------------------------------------------------------
    async def on_start(self) -> None:
        ep = self.endpoint
        # A task_request that is not one is answered (an error and the ack): the handler reads
        # the payload model itself (message.typed) instead of having it dropped.
        self.subscribe(ep, "task_request", self.hub_requests.on_task_request)
        self.on(ep, TaskStarted, self.reports.on_task_started)
        self.on(ep, TaskEnded, self.reports.on_task_ended)
        self.on(ep, TourProgress, self.reports.on_tour_progress)
        self.on(ep, RobotState, self.presence.on_robot_state)
        self.on(ep, RobotLink, self.presence.on_robot_disconnected, types=["robot_disconnected"])
        self.on(ep, SiteLoaded, self.news.robot_connected)  # on every robot's connect
        self.on(ep, BatteryAlarm, self.battery.on_battery_low, types=["battery_low"])
        self.on(ep, BatteryAlarm, self.battery.on_battery_panic, types=["battery_panic"])
        self.subscribe(ep, "closures_changed", self._on_closures_changed)  # news, no payload
        for unsubscribe in listen(self.endpoint, self.courier):
            self.on_cleanup(unsubscribe)
        self.on_cleanup(self._finish)
        if self.tick_s is not None:  # None: whoever drives the clock calls check_timeouts
            self.spawn(self.watchdog.run(self.tick_s), name="task-manager-watchdog")

    def _on_closures_changed(self, _msg: Message) -> None:
        """Trouble raised or lifted: the visitors waiting for it are told (task_event with
        ``trouble``), and those whose way is open again are given out at once (trouble.py)."""
        for task_id in self.trouble.waiting():
            task = self.tasks.get(task_id)
            if task is not None and task.state is TaskState.QUEUED:
                self.publish_event(task)
        self.dispatch()

    async def _finish(self) -> None:
        """Stop: retries end, and task writes in flight get 5 s to reach the database."""
        self.courier.close()
        await self.hub_requests.finish_writes()

    def load_site(self, site: Site, graph: SiteGraph | None = None) -> None:
        """New site while running: robots added or removed, new map for costs."""
        self.site = site
        self.graph = graph or SiteGraph(site)
        self.lifts.site_changed(site)
        self.estimator.site_changed()
        self._net_params.clear()
        for cfg in site.robots:
            info = self.robots.get(cfg.name)
            if info is None:
                self.book.add_robot(RobotInfo(cfg.name, cfg, node=cfg.start_node))
            else:
                info.config = cfg
        on_site = {cfg.name for cfg in site.robots}
        for name in [n for n in self.robots if n not in on_site]:
            info = self.robots[name]
            if info.current is not None:
                self.requeue(self.tasks[info.current], "robot removed from the site")
            self.book.remove_robot(name)
        for task in [t for t in self.queue.ordered()]:
            try:
                self.target_of(task.kind, task.params)
            except TaskError as exc:
                self.book.withdraw(task)
                task.move(TaskState.CANCELLED, reason=f"the site changed: {exc}")
                self.changed(task, "cancelled")
        self.dispatch()

    def restore(self, tasks: list[Task]) -> None:
        """After a restart: queued tasks queue again; running ones await their robot's word."""
        for task in sorted(tasks, key=lambda t: t.seq):
            if task.state is TaskState.QUEUED:
                self.book.enqueue(task)
                continue
            self.book.add(task)
            if (robot := self.robots.get(task.robot or "")) is not None:
                self.book.restored(task, robot, self.clock())
            elif not task.final:
                self.book.requeue(task, "robot unknown after restart")
                self.changed(task, "requeued")
        last = max((t.seq for t in tasks), default=0)
        self._seq = itertools.count(last + 1)
        self.dispatch()

    def restore_service(self, out: dict[str, str]) -> None:
        """After a restart: the robots staff had left out of service (robot -> by whom) are
        out of service again; one no longer on the site is ignored."""
        for name in out:
            robot = self.robots.get(name)
            if robot is not None:
                robot.out_of_service = True

    # --- requests (API, buttons, robots) -------------------------------------------------
    def request(
        self,
        kind: str,
        params: dict[str, Any] | None = None,
        *,
        priority: int = 5,
        requester: str = "",
        robot: str | None = None,
        internal: bool = False,
    ) -> Task:
        """Queue a task; raises TaskError if its parameters do not fit the site."""
        params = validate_params(kind, params if params is not None else {})
        self.target_of(kind, params)  # the references exist in the site
        if "lang" in params and params["lang"] not in (offered := site_languages(self.site)):
            raise InvalidTask(f"language {params['lang']!r} not offered (offered: {offered})")
        if robot is not None and robot not in self.robots:
            raise InvalidTask(f"unknown robot {robot!r}")
        if not internal and self.hold is not None:
            if (why := self.hold.refusal(params.get("lang"))) is not None:
                raise Held(why)
        if not internal and self.queue.full:
            raise QueueFull(f"the queue is full ({self.queue.maxsize} tasks waiting)")
        task = Task(
            id=uuid.uuid4().hex[:12],
            kind=kind,
            params=params,
            priority=priority,
            requester=requester,
            seq=next(self._seq),
            pinned_robot=robot,
            internal=internal,
        )
        self.book.enqueue(task)
        self.changed(task, "created")
        self.dispatch()
        return task

    def get(self, task_id: str) -> Task:
        task = self.tasks.get(task_id)
        if task is None:
            raise TaskNotFound(f"no task {task_id!r}")
        return task

    def cancel(
        self, task_id: str, *, reason: str = "cancelled", by: str = "", by_role: str = ""
    ) -> Task:
        """``by_role`` ("staff" or "requester") goes out with the task_event: the visitor is
        told who cancelled a request (docs/visitor.md)."""
        task = self.get(task_id)
        if task.final:
            raise TaskFinished(f"task {task_id} is already {task.state.value}")
        self._leave_robot(task, f"{reason} by {by}".strip())
        task.cancelled_by = by_role
        task.move(TaskState.CANCELLED, reason=f"{reason} ({by})" if by else reason)
        self.changed(task, "cancelled")
        self.dispatch()
        return task

    def reprioritise(self, task_id: str, priority: int) -> Task:
        task = self.get(task_id)
        if task.final:
            raise TaskFinished(f"task {task_id} is already {task.state.value}")
        task.priority = priority
        task.version += 1
        if task.state is TaskState.QUEUED:
            self.book.enqueue(task)
        self.changed(task, "reprioritised")
        self.dispatch()
        return task

    def reassign(self, task_id: str, robot: str | None = None, *, by: str = "") -> Task:
        """Take a task off its robot (even a broken one) and give it to ``robot`` or the
        next free robot but that one."""
        task = self.get(task_id)
        if task.final:
            raise TaskFinished(f"task {task_id} is already {task.state.value}")
        if robot is not None and robot not in self.robots:
            raise InvalidTask(f"unknown robot {robot!r}")
        old = task.robot
        if old is not None:
            self.book.avoid(task.id, old)
        task.pinned_robot = robot
        if robot is not None:
            self.book.allow(task.id, robot)
        if task.state is TaskState.QUEUED:
            task.version += 1
            self.book.enqueue(task)
            self.changed(task, "reassigned")
        else:
            self.requeue(task, f"reassigned by {by}".strip())
        self.dispatch()
        return task

    def set_out_of_service(self, name: str, out: bool, *, by: str = "") -> RobotInfo:
        """Take a robot out of service (its task goes back to the queue for another robot)
        or put it back. Out of service it gets no tasks, not even going home, except the
        go_to and charge tasks staff pin to it (moving it by hand)."""
        robot = self.robots.get(name)
        if robot is None:
            raise TaskNotFound(f"no robot {name!r}")
        if robot.out_of_service == out:
            return robot
        robot.out_of_service = out
        if self.store is not None:
            self.store.record_service(name, out, by)
        current = self.current_of(robot)
        if out and current is not None and not current.final:
            if current.internal:
                self.cancel(current.id, reason="robot out of service", by=by)
            else:
                self.reassign(current.id, None, by=by)
        self.endpoint.publish(RobotService(robot=name, out_of_service=out, by=by))
        self.dispatch()
        return robot

    def send_to_charge(self, name: str, *, by: str = "", priority: int = 10) -> Task:
        """Staff send a robot to charge (the console): a charge task pinned to it, at the
        station it stands at, else the nearest free one (else the nearest: it waits there).
        A robot on a visitor's task goes after it; it takes no new tour meanwhile."""
        robot = self.robots.get(name)
        if robot is None:
            raise TaskNotFound(f"no robot {name!r}")
        if not self.site.charging_stations:
            raise InvalidTask("the site has no charging station")
        taken = {
            t.params.get("station")
            for r in self.robots.values()
            if r.name != name and (t := self.current_of(r)) is not None and t.kind == "charge"
        }
        taken |= {
            s.id
            for s in self.site.charging_stations
            for r in self.robots.values()
            if r.name != name and r.node == s.node
        }
        station = station_for(robot, self.site, taken, self.graph.distances_to)
        assert station is not None
        return self.request(
            "charge", {"station": station.id}, priority=priority, requester=by, robot=name
        )

    def queue_position(self, task: Task) -> int | None:
        return self.queue.position(task) if task.state is TaskState.QUEUED else None

    def eta_s(self, task: Task) -> float | None:
        """Estimated wait before a robot starts on it (backend/tasks/eta.py)."""
        return self.estimator.estimate(task).wait_s

    def status(self, task: Task) -> dict[str, Any]:
        """The task as ``GET /api/tasks/{id}`` shows it; a finished tour keeps its last
        progress (how far it went, the stops it skipped)."""
        return {
            **task.as_dict(),
            "queue_position": self.queue_position(task),
            **self.estimator.estimate(task).as_dict(),
            "progress": self.estimator.progress_view(task),
            "trouble": self.trouble_view(task),
        }

    def trouble_view(self, task: Task) -> dict[str, Any] | None:
        """A queued task waiting for trouble on its way to lift: what its visitor is told."""
        if task.state is not TaskState.QUEUED:
            return None
        return self.trouble.view(task.id, self.closed_now())

    def closed_now(self) -> Mapping[str, object]:
        """Node -> the closure that takes it out now (backend/closures); empty without it."""
        return self.estimator.closed() if self.estimator.closed is not None else {}

    # --- assignment ----------------------------------------------------------------------
    def set_paused(self, paused: bool) -> None:
        """Staff pause the fleet: no queued task is given to a robot and no idle robot is sent
        anywhere until they resume; running tasks go on (docs/console.md, "Fleet"). Queued
        visitors are told the service is paused, with no wait, until then (eta.py)."""
        self.paused = paused
        self.estimator.paused = paused
        self.news.changed()
        if not paused:
            self.dispatch()

    def dispatch(self) -> None:
        """Give queued tasks to available robots, best first; then send idle robots home."""
        if self.paused:
            return
        if self._dispatching:
            self._dispatch_again = True
            return
        self._dispatching = True
        try:
            again = True
            while again:
                self._dispatch_again = False
                self._assign_queued()
                self._send_idle_robots()
                again = self._dispatch_again
        finally:
            self._dispatching = False

    def _available(self, robot: RobotInfo) -> bool:
        if self.hold is not None and self.hold.holds(robot):
            return False
        return available(robot, self.current_of(robot))

    def has_free_robot(self) -> bool:
        """A robot could start a main task now: idle as far as tasks go, and available (the
        visitors' "available" service, backend/tasks/eta.py)."""
        robots = self.robots
        return any(
            (r := robots.get(n)) is not None and r.online and self._available(r)
            for n in self.book.idle
        )

    def _assign_queued(self) -> None:
        robots = self.robots
        # ``online`` first: before its robots report, a fleet is idle but not available.
        free = {n: r for n in self.book.idle if (r := robots[n]).online and self._available(r)}
        if not free or not len(self.queue):
            return
        plan: list[tuple[Task, RobotInfo]] = []
        timed = self.assign_times_ms is not None
        closed = self.closed_now()
        for task in self.queue.head():
            if self.trouble.held(task.id, closed):
                continue  # its way is out of order for a while (trouble.py)
            t0 = time.perf_counter() if timed else 0.0
            try:
                best = self._best_robot(task, free)
            except TaskError:
                continue  # cannot happen after load_site's check; never stop the others
            if best is None:
                continue
            plan.append((task, best))
            del free[best.name]
            if timed and self.assign_times_ms is not None:
                self.assign_times_ms.append((time.perf_counter() - t0) * 1000)
            if not free:
                break
        for task, robot in plan:
            self._assign(task, robot)

    def _best_robot(self, task: Task, free: dict[str, RobotInfo]) -> RobotInfo | None:
        target = self.target_of(task.kind, task.params)
        first = self.estimator.first_node(task) or target  # a handed-over tour: the visitor
        if self.reservations is not None:
            free = {n: r for n, r in free.items() if not self.reservations.keeps(r, task)}
        return choose_robot(
            task,
            free,
            lambda: self.graph.distances_to(first),
            avoid=self.book.avoided(task.id),
            rather_not=self.book.rather_not_robots(task.id),
            extra_cost=lambda robot: self.lift_wait_s(robot.node, first),
            fits=(lambda robot: self._lasts(robot, task)),
        )

    def lift_wait_s(self, start: str | None, goal: str) -> float:
        """Seconds a robot at ``start`` waits for a lift to ``goal``'s floor behind the robots
        in the lifts' queue (backend/tasks/lifts.py; the queue read at most once a second)."""
        now = self.clock()
        cached = self._lift_queued
        if cached is None or now - cached[0] > 1.0:
            cached = self._lift_queued = (now, self.lifts.queued())
        return self.lifts.wait_s(self.graph, start, goal, cached[1])

    def _assign(self, task: Task, robot: RobotInfo) -> None:
        if robot.current is not None:
            previous = self.tasks.get(robot.current)
            if previous is not None and not previous.final:
                self.send_cancel(robot.name, previous.id, "preempted by a main task")
                previous.move(TaskState.CANCELLED, reason="preempted by a main task")
                self.changed(previous, "cancelled")
        task.net = NETS[task.kind]
        task.assigned_params = self._params_for_net(task)
        task.move(TaskState.ASSIGNED, reason="")
        self.book.give(task, robot, self.clock())
        self.send_assigned(task, robot)
        self.changed(task, "assigned")

    def _params_for_net(self, task: Task) -> dict[str, Any]:
        """``net_params`` looked up once per kind and parameters on this site (the texts of a
        tour's five points are the same for every visitor who asks for it); a handed-over tour
        gets its points from the visitor's stop on (backend/tasks/handover.py)."""
        return resumed_points(self._site_params_for_net(task), task.resume_from)

    def _site_params_for_net(self, task: Task) -> dict[str, Any]:
        try:
            key = (task.kind, tuple(sorted(task.params.items())))
            found = self._net_params.get(key)
        except TypeError:  # a parameter that is not hashable: not worth keeping
            return net_params(self.site, task)
        if found is None:
            found = self._net_params[key] = net_params(self.site, task)
        return found

    def send_assigned(self, task: Task, robot: RobotInfo) -> None:
        """task_assigned, sent again until the robot acknowledges it (guidebot/delivery.py)."""
        assigned = make_message(
            TaskAssigned(
                task_id=task.id,
                robot=robot.name,
                net=task.net,
                params=task.assigned_params,
                handover=task.handover_view(),
            ),
            source=self.endpoint.name,
            destination=robot.name,
        )
        self.courier.post(assigned, key=("task", task.id, robot.name))

    def _send_idle_robots(self) -> None:
        """Robots with nothing to do: charge if they must, else a free station, else the
        wait point (backend/tasks/choice.py, ``idle_errands``)."""
        robots = self.robots
        # A robot that refused a task waits for its next robot_state (backend/tasks/reports.py):
        # an errand now would be refused too, and a robot that refuses at once (in-process,
        # a VDA 5050 vehicle) would make dispatch loop for ever.
        idle = [
            r
            for n in self.book.idle
            if (r := robots.get(n)) is not None and r.online and not r.refused
        ]
        if self.hold is not None:
            idle = [r for r in idle if not self.hold.holds(r)]
        if self.reservations is not None:
            idle = [r for r in idle if not self.reservations.parks(r)]
        if not idle:
            return  # the usual case: nothing below needs the whole fleet (offline robots
            # have no errands: idle_errands skips them too)
        charging_at = [
            t.params.get("station")
            for r in self.robots.values()
            if (t := self.current_of(r)) is not None and t.kind == "charge"
        ]
        closed = self.closed_now()
        now = self.clock()
        errands = idle_errands(
            idle,
            self.robots.values(),
            charging_at,
            self.site,
            self.graph.distances_to,
            lambda robot: self._available(robot) and self._work_for(robot) == "work",
            lambda robot, node: (
                self.blocked.barred(robot.name, robot.node, node, closed, now) is not None
            ),
            short=lambda robot: self._available(robot) and self._work_for(robot) == "short",
        )
        for robot, kind, params in errands:
            self._internal(robot, kind, params)

    def errand_failed(self, robot: RobotInfo, task: Task, trouble: bool = False) -> None:
        """An idle robot's errand (``task``: internal, charge or go_to) failed (``trouble``:
        its task_ended's flag): its target is not given to it again until something changes
        (blocked.py); a charge so barred raises one alert for staff (``charge_unreachable``,
        the robot), resolved when it charges."""
        try:
            goal = self.target_of(task.kind, task.params)
        except TaskError:
            return
        targets = [s.node for s in self.site.charging_stations]
        targets += [w.node for w in self.site.wait_points]
        bar = self.blocked.failed(
            robot.name,
            robot.node,
            goal,
            targets,
            self.graph,
            self.closed_now(),
            self.clock(),
            kind=task.kind,
            trouble=trouble,
        )
        if bar is None or task.kind != "charge" or not robot.needs_charge:
            return
        if self.alerts is None or self.alerts.is_active(CHARGE_UNREACHABLE, robot.name):
            return
        closed, now = self.closed_now(), self.clock()
        if any(
            self.blocked.barred(robot.name, robot.node, s.node, closed, now) is None
            for s in self.site.charging_stations
        ):
            return  # another station is open to it: it goes there
        then = (
            "it goes when that works again"
            if bar.closures
            else f"it tries again in {bar.until - now:.0f} s"
        )
        self.alerts.raise_(
            CHARGE_UNREACHABLE,
            robot.name,
            f"{robot.name} needs to charge and cannot reach a charging station: {bar.why}; {then}",
            "warning",
        )

    def errand_done(self, robot: RobotInfo, where: str) -> None:
        """An idle robot reached its errand's target (a charge done, its wait point, a
        station): its failed errands are forgotten, its alert resolved."""
        if not self.blocked.any_bars(robot.name):
            return
        self.blocked.clear(robot.name)
        if self.alerts is not None:
            self.alerts.resolve(CHARGE_UNREACHABLE, robot.name, f"{robot.name} reached {where}")

    def moved_to(self, robot: RobotInfo) -> None:
        """A robot_state places ``robot`` on a new node: at a charging station, the errands it
        failed are forgotten (it got there after all)."""
        if self.blocked.any_bars(robot.name) and any(
            s.node == robot.node for s in self.site.charging_stations
        ):
            self.errand_done(robot, f"charging station at {robot.node}")

    def _lasts(self, robot: RobotInfo, task: Task) -> bool:
        """Its battery lasts ``task`` (charging.py ``can_finish``); a charge or a move by
        staff goes regardless."""
        if task.kind not in VISITOR_KINDS:
            return True
        return can_finish(robot, self.estimator.task_s(task, robot.node))

    def _work_for(self, robot: RobotInfo) -> str:
        """What the queue holds for an idle robot: ``work``, a task it may take (not one its
        booking keeps it from: it charges or waits for its booked tour meanwhile, backend/
        bookings/reserve.py) and can finish on its battery; ``short``, only tasks its battery
        would not last now but would once charged (it charges, then takes one: choice.py
        ``idle_errands``); ``none``.
        Past ``SHORT_LOOK`` tasks it would not last, it is short (a long queue is not read
        through at every dispatch)."""
        kept = self.reservations
        short = 0
        for task in self.queue.head():
            if task.pinned_robot not in (None, robot.name) or (
                kept is not None and kept.keeps(robot, task)
            ):
                continue
            if task.kind not in VISITOR_KINDS:
                return "work"
            took = self.estimator.task_s(task, robot.node)
            charge_s = charge_first_s(robot, robot.battery, took, self.robots.values())
            if charge_s <= 0:
                return "work"
            if math.isinf(charge_s):
                continue  # not even a full charge lasts it: no reason to charge for it
            short += 1
            if short >= SHORT_LOOK:
                break
        return "short" if short else "none"

    def _internal(self, robot: RobotInfo, kind: str, params: dict[str, Any]) -> None:
        task = Task(
            id=uuid.uuid4().hex[:12],
            kind=kind,
            params=params,
            priority=0,
            requester="task_manager",
            seq=next(self._seq),
            pinned_robot=robot.name,
            internal=True,
        )
        self.book.add(task)
        self.changed(task, "created")
        self._assign(task, robot)

    def check_timeouts(self) -> None:
        """Silent robots, lost robots' tasks, tasks nobody started (backend/tasks/watchdog.py)."""
        self.watchdog.check()

    # --- what the parts share --------------------------------------------------------------
    def robot_of(self, msg: Message, name: str) -> RobotInfo | None:
        """The robot ``name`` a message (its payload's ``robot``) is about; None if unknown, or
        if a robot speaks for another one."""
        if name not in self.robots:
            return None
        if msg.source in self.robots and msg.source != name:
            return None  # a robot speaks only for itself
        return self.robots[name]

    def current_of(self, robot: RobotInfo) -> Task | None:
        """The task the robot holds (None: none, or one no longer in memory)."""
        return self.book.current_of(robot)

    def requeue(self, task: Task, reason: str) -> None:
        """Back to the queue in its old place (same priority and arrival order), its robot told
        to stop it; an internal task, or one the site no longer has room for, is cancelled."""
        if task.internal:
            self._leave_robot(task, reason)
            task.move(TaskState.CANCELLED, reason=reason)
            self.changed(task, "cancelled")
            return
        if task.state in (TaskState.ASSIGNED, TaskState.RUNNING):
            note_break(task, self.estimator, reason)  # a tour goes on from the visitor's stop
            if task.resume_from:  # its wait is foretold from there too (eta.py)
                task.assigned_params = resumed_points(task.assigned_params, task.resume_from)
        try:
            self.target_of(task.kind, task.params)
        except TaskError as exc:  # the site changed under it: nothing to go back to
            self._leave_robot(task, reason)
            task.move(TaskState.CANCELLED, reason=f"{reason}; the site changed: {exc}")
            self.changed(task, "cancelled")
            return
        self._tell_robot_to_stop(task, reason)
        self.book.requeue(task, reason)
        self.changed(task, "requeued")

    def _leave_robot(self, task: Task, reason: str) -> None:
        """Its robot is told to stop it; the book takes it off the robot and the queue."""
        self._tell_robot_to_stop(task, reason)
        self.book.withdraw(task)

    def _tell_robot_to_stop(self, task: Task, reason: str) -> None:
        if task.robot is not None and task.state in (TaskState.ASSIGNED, TaskState.RUNNING):
            self.send_cancel(task.robot, task.id, reason)

    def send_cancel(self, robot: str, task_id: str, reason: str) -> None:
        # Replaces an unacknowledged task_assigned of this task (same key): the robot gets the
        # cancel, never a late copy of the assignment after it.
        cancel = make_message(
            TaskCancel(task_id=task_id, reason=reason),
            source=self.endpoint.name,
            destination=robot,
        )
        self.courier.post(cancel, key=("task", task_id, robot))

    def target_of(self, kind: str, params: dict[str, Any]) -> str:
        """Where a ``kind`` task starts (for path cost); raises InvalidTask (a TaskError) if
        ``params`` name what the site does not have."""
        return target_node(self.site, self.graph, kind, params)

    def event(self, task: Task) -> TaskEvent:
        """The task_event of a task as it stands (for GUIs, panels, the requester)."""
        return TaskEvent(
            task_id=task.id,
            state=task.state.value,
            robot=task.robot,
            queue_position=self.queue_position(task),
            **self.estimator.estimate(task).as_dict(),
            progress=self.estimator.progress_view(task),
            reason=task.reason,
            cancelled_by=task.cancelled_by,
            handover=task.handover_view(),
            trouble=self.trouble_view(task),
        )

    def publish_event(self, task: Task) -> None:
        """The task's task_event on the hub, remembered as what its visitor was told."""
        event = self.event(task)
        self.endpoint.publish(event)
        self.news.told(event)

    def changed(self, task: Task, event: str) -> None:
        """Every state change: an event on the hub and a row in the task's history."""
        self.estimator.changed(task, event)
        if self.store is not None:
            self.store.record(task, event)
        self.publish_event(task)
        if task.final:
            self.trouble.forget(task.id)
        self.book.changed(task)
