"""The Task Manager: queue, assignment by path cost/battery/availability, battery alarms,
robot loss and reconciliation after a restart (docs/server.md).

Handlers run inline on the bus and never block: persistence goes through a write-behind
``TaskStore``; a watchdog task checks silent robots and tasks nobody started.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable
from typing import Any, Protocol

from pydantic import ValidationError

from backend.tasks.choice import available, choose_robot, nearest
from backend.tasks.eta import EtaEstimator
from backend.tasks.model import (
    FINAL_STATES,
    InvalidTask,
    QueueFull,
    Task,
    TaskError,
    TaskFinished,
    TaskNotFound,
    TaskState,
)
from backend.tasks.params import validate_params
from backend.tasks.queue import TaskQueue
from backend.tasks.robots import RobotInfo
from guidebot.bus import BusEndpoint
from guidebot.delivery import ack_for, courier_for, listen
from guidebot.messages import Message
from guidebot.payloads.tasks import TaskRequest, TourProgress
from guidebot.service import Service
from guidebot.site.graph import SiteGraph
from guidebot.site.i18n import poi_texts, resolve_language, site_languages
from guidebot.site.schema import Site
from guidebot.task_kinds import KINDS, UnknownTarget

__all__ = ["TaskManager", "TaskStore"]

log = logging.getLogger(__name__)

NETS = {kind: spec.net for kind, spec in KINDS.items()}
DEFAULT_DURATION_S = {kind: spec.duration_s for kind, spec in KINDS.items()}
MAX_FINISHED_IN_MEMORY = 5000
MAX_REMEMBERED_REQUESTS = 4096


class TaskStore(Protocol):
    """Where tasks and their history go (backend.db.store.DbTaskStore); must not block."""

    def record(self, task: Task, event: str) -> None: ...


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
        tick_s: float | None = 0.5,
        max_queued: int = 100_000,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.store = store
        self.robot_timeout_s = robot_timeout_s
        self.lost_grace_s = lost_grace_s
        self.start_timeout_s = start_timeout_s
        self.tick_s = tick_s
        self.clock = clock
        self.tasks: dict[str, Task] = {}
        self.queue = TaskQueue(max_queued)
        self.robots: dict[str, RobotInfo] = {}
        self._seq = itertools.count(1)
        self._finished: list[str] = []
        self._assigned_at: dict[str, float] = {}
        self._unconfirmed: set[str] = set()
        self._avoid: dict[str, set[str]] = {}
        """Task -> robots it must not go to (staff reassigned it away from them)."""
        self._rather_not: dict[str, set[str]] = {}
        """Task -> robots it was taken from (lost, battery panic): used only if no other is free."""
        self._durations: dict[str, float] = dict(DEFAULT_DURATION_S)
        self._writes: set[asyncio.Task[None]] = set()
        self._requests: OrderedDict[tuple[str, str], str] = OrderedDict()
        """(requester, message id) of hub task_requests -> their task: a repeat is not new."""
        self._dispatching = False
        self._dispatch_again = False
        self._idle: set[str] = set()
        """Robots free for a main task as far as tasks go: nothing, or an internal task."""
        self.assign_times_ms: list[float] | None = None
        self.site = site
        self.graph = graph or SiteGraph(site)
        self.estimator = EtaEstimator(self)
        """Waits, arrivals and durations told to visitors (backend/tasks/eta.py)."""
        self.courier = courier_for(endpoint)
        """task_assigned and task_cancel: sent again until the robot acknowledges them."""
        self.load_site(site, self.graph)

    # --- life cycle ----------------------------------------------------------------------
    async def on_start(self) -> None:
        self.subscribe_all(
            self.endpoint,
            {
                "task_request": self._on_task_request,
                "task_started": self._on_task_started,
                "task_ended": self._on_task_ended,
                "robot_state": self._on_robot_state,
                "battery_low": self._on_battery_low,
                "battery_panic": self._on_battery_panic,
                "robot_disconnected": self._on_robot_disconnected,
                "tour_progress": self._on_tour_progress,
            },
        )
        for unsubscribe in listen(self.endpoint, self.courier):
            self.on_cleanup(unsubscribe)
        self.on_cleanup(self._finish_writes)
        if self.tick_s is not None:  # None: whoever drives the clock calls check_timeouts
            self.spawn(self._watch(), name="task-manager-watchdog")

    async def _finish_writes(self) -> None:
        """Stop: retries end, and task writes in flight get 5 s to reach the database."""
        self.courier.close()
        if self._writes:
            with contextlib.suppress(TimeoutError):  # a database that never answers
                async with asyncio.timeout(5.0):
                    await asyncio.gather(*self._writes, return_exceptions=True)
            for writing in self._writes:
                writing.cancel()

    def load_site(self, site: Site, graph: SiteGraph | None = None) -> None:
        """New site while running: robots added or removed, new map for costs."""
        self.site = site
        self.graph = graph or SiteGraph(site)
        for cfg in site.robots:
            info = self.robots.get(cfg.name)
            if info is None:
                self.robots[cfg.name] = RobotInfo(cfg.name, cfg, node=cfg.start_node)
                self._idle.add(cfg.name)
            else:
                info.config = cfg
        for name in [n for n in self.robots if site.robot(n) is None]:
            info = self.robots[name]
            if info.current is not None:
                self._requeue(self.tasks[info.current], "robot removed from the site")
            del self.robots[name]
            self._idle.discard(name)
        for task in [t for t in self.queue.ordered()]:
            try:
                self._target_node(task.kind, task.params)
            except TaskError as exc:
                self.queue.remove(task.id)
                task.move(TaskState.CANCELLED, reason=f"the site changed: {exc}")
                self._changed(task, "cancelled")
        self.dispatch()

    def restore(self, tasks: list[Task]) -> None:
        """After a restart: queued tasks queue again; running ones await their robot's word."""
        for task in sorted(tasks, key=lambda t: t.seq):
            self.tasks[task.id] = task
            if task.state is TaskState.QUEUED:
                self.queue.push(task)
            elif task.robot in self.robots:
                self._set_current(self.robots[task.robot], task.id)
                self._unconfirmed.add(task.id)
                self._assigned_at[task.id] = self.clock()
            elif not task.final:
                task.move(TaskState.QUEUED, reason="robot unknown after restart")
                task.robot = None
                self.queue.push(task)
                self._changed(task, "requeued")
        last = max((t.seq for t in tasks), default=0)
        self._seq = itertools.count(last + 1)
        self.dispatch()

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
        self._target_node(kind, params)  # the references exist in the site
        if "lang" in params and params["lang"] not in (offered := site_languages(self.site)):
            raise InvalidTask(f"language {params['lang']!r} not offered (offered: {offered})")
        if robot is not None and robot not in self.robots:
            raise InvalidTask(f"unknown robot {robot!r}")
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
        self.tasks[task.id] = task
        self.queue.push(task)
        self._changed(task, "created")
        self.dispatch()
        return task

    def get(self, task_id: str) -> Task:
        task = self.tasks.get(task_id)
        if task is None:
            raise TaskNotFound(f"no task {task_id!r}")
        return task

    def cancel(self, task_id: str, *, reason: str = "cancelled", by: str = "") -> Task:
        task = self.get(task_id)
        if task.final:
            raise TaskFinished(f"task {task_id} is already {task.state.value}")
        self._leave_robot(task, f"{reason} by {by}".strip())
        self.queue.remove(task.id)
        task.move(TaskState.CANCELLED, reason=f"{reason} ({by})" if by else reason)
        self._changed(task, "cancelled")
        self.dispatch()
        return task

    def reprioritise(self, task_id: str, priority: int) -> Task:
        task = self.get(task_id)
        if task.final:
            raise TaskFinished(f"task {task_id} is already {task.state.value}")
        task.priority = priority
        task.version += 1
        if task.state is TaskState.QUEUED:
            self.queue.push(task)
        self._changed(task, "reprioritised")
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
            self._avoid.setdefault(task.id, set()).add(old)
        task.pinned_robot = robot
        if robot is not None:
            self._avoid.get(task.id, set()).discard(robot)
        if task.state is TaskState.QUEUED:
            task.version += 1
            self.queue.push(task)
            self._changed(task, "reassigned")
        else:
            self._requeue(task, f"reassigned by {by}".strip())
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
        current = self.tasks.get(robot.current) if robot.current else None
        if out and current is not None and not current.final:
            if current.internal:
                self.cancel(current.id, reason="robot out of service", by=by)
            else:
                self.reassign(current.id, None, by=by)
        self.endpoint.publish("robot_service", {"robot": name, "out_of_service": out, "by": by})
        self.dispatch()
        return robot

    def queue_position(self, task: Task) -> int | None:
        return self.queue.position(task) if task.state is TaskState.QUEUED else None

    def eta_s(self, task: Task) -> float | None:
        """Estimated wait before a robot starts on it (backend/tasks/eta.py)."""
        return self.estimator.estimate(task).wait_s

    def status(self, task: Task) -> dict[str, Any]:
        return {
            **task.as_dict(),
            "queue_position": self.queue_position(task),
            **self.estimator.estimate(task).as_dict(),
            "progress": self.estimator.progress_view(task),
        }

    # --- assignment ----------------------------------------------------------------------
    def dispatch(self) -> None:
        """Give queued tasks to available robots, best first; then send idle robots home."""
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
        return available(robot, self.tasks.get(robot.current) if robot.current else None)

    def _assign_queued(self) -> None:
        robots = self.robots
        free = {n: robots[n] for n in self._idle if self._available(robots[n])}
        if not free or not len(self.queue):
            return
        plan: list[tuple[Task, RobotInfo]] = []
        timed = self.assign_times_ms is not None
        for task in self.queue.head():
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
        return choose_robot(
            task,
            free,
            lambda: self.graph.distances_to(self._target_node(task.kind, task.params)),
            avoid=self._avoid.get(task.id, ()),
            rather_not=self._rather_not.get(task.id, ()),
        )

    def _assign(self, task: Task, robot: RobotInfo) -> None:
        if robot.current is not None:
            previous = self.tasks.get(robot.current)
            if previous is not None and not previous.final:
                self._send_cancel(robot.name, previous.id, "preempted by a main task")
                previous.move(TaskState.CANCELLED, reason="preempted by a main task")
                self._changed(previous, "cancelled")
        self.queue.remove(task.id)
        task.robot = robot.name
        task.net = NETS[task.kind]
        task.assigned_params = self._net_params(task)
        task.move(TaskState.ASSIGNED, reason="")
        self._set_current(robot, task.id)
        self._assigned_at[task.id] = self.clock()
        self._unconfirmed.discard(task.id)
        self._send_assigned(task, robot)
        self._changed(task, "assigned")

    def _send_assigned(self, task: Task, robot: RobotInfo) -> None:
        assigned = Message(
            type="task_assigned",
            source=self.endpoint.name,
            destination=robot.name,
            payload={
                "task_id": task.id,
                "robot": robot.name,
                "net": task.net,
                "params": task.assigned_params,
            },
        )
        self.courier.post(assigned, key=("task", task.id, robot.name))

    def _send_idle_robots(self) -> None:
        """Robots with nothing to do: charge if they must, else a free station, else the
        wait point."""
        idle = [
            r
            for n in self._idle
            if (r := self.robots[n]).current is None
            and r.online
            and not r.fault
            and not r.out_of_service
        ]
        if not idle:
            return
        taken: set[str | None] = set()
        for r in self.robots.values():
            current = self.tasks.get(r.current) if r.current else None
            if current is not None and current.kind == "charge":
                taken.add(current.params.get("station"))
        at = {s.node: s.id for s in self.site.charging_stations}
        taken |= {at[r.node] for r in self.robots.values() if r.node in at}
        wait_nodes = {w.node for w in self.site.wait_points}
        free_stations = [s for s in self.site.charging_stations if s.id not in taken]
        for robot in idle:
            if robot.current is not None:
                continue
            if self._available(robot) and self._has_work_for(robot):
                continue
            if robot.node in at:
                if robot.needs_charge and robot.mode != "charging":
                    self._internal(robot, "charge", {"station": at[robot.node]})
                continue
            if robot.node in wait_nodes and not robot.needs_charge:
                continue
            station = self._nearest(robot, [s for s in free_stations if s.id not in taken])
            if station is not None:
                taken.add(station.id)
                self._internal(robot, "charge", {"station": station.id})
            elif not robot.needs_charge:
                wait = self._nearest(robot, list(self.site.wait_points))
                if wait is not None:
                    self._internal(robot, "go_to", {"node": wait.node})

    def _has_work_for(self, robot: RobotInfo) -> bool:
        for task in self.queue.head():
            if task.pinned_robot in (None, robot.name):
                return True
        return False

    def _nearest(self, robot: RobotInfo, places: list[Any]) -> Any:
        return nearest(robot.node, places, self.graph.distances_to)

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
        self.tasks[task.id] = task
        self._changed(task, "created")
        self._assign(task, robot)

    # --- robot messages ------------------------------------------------------------------
    def _on_task_request(self, msg: Message) -> None:
        # A repeat (the robot's link sends it again until answered): the same task, answered
        # again, never a second one.
        key = (msg.source, msg.id)
        known = self.tasks.get(self._requests.get(key, ""))
        if known is not None:
            self._answer_when_written(msg, self._event_payload(known))
            return
        try:
            req: TaskRequest = msg.payload_as(TaskRequest)
            robot = msg.source if msg.source in self.robots else None
            # A robot requests as itself; in-process modules (buttons, RGM) may name a requester.
            requester = msg.source if robot is not None else (req.requester or msg.source)
            # A visitor at a robot's screen: that robot takes it.
            task = self.request(
                req.kind, req.params, priority=req.priority, requester=requester, robot=robot
            )
        except (ValidationError, TaskError) as exc:
            reason = str(exc) if isinstance(exc, TaskError) else exc.errors()[0]["msg"]
            refusal = {"code": "task_refused", "reason": reason, "message_id": msg.id}
            self._reply(msg, "error", refusal)
            self.endpoint.send(ack_for(msg, self.endpoint.name))  # a copy would be refused too
            return
        self._requests[key] = task.id
        if len(self._requests) > MAX_REMEMBERED_REQUESTS:
            self._requests.popitem(last=False)
        self._answer_when_written(msg, self._event_payload(task))

    def _answer_when_written(self, msg: Message, payload: dict[str, Any]) -> None:
        """The task_event answer and the ack leave once the task is in the database (as REST
        answers with a broker): an acknowledged request survives a crash right after. Without
        a store that can flush (unit tests) or an event loop, at once."""
        flush = getattr(self.store, "flush", None)
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            loop = None
        if flush is None or loop is None:
            self._answer(msg, payload)
            return
        writing = loop.create_task(self._reply_after(flush, msg, payload), name="task-written")
        self._writes.add(writing)
        writing.add_done_callback(self._writes.discard)

    async def _reply_after(
        self, flush: Callable[[], Any], msg: Message, payload: dict[str, Any]
    ) -> None:
        try:
            await flush()
        except Exception as exc:  # the store keeps it and writes it when the database is back
            log.warning("task %s answered before it was written: %r", payload.get("task_id"), exc)
        self._answer(msg, payload)

    def _answer(self, msg: Message, payload: dict[str, Any]) -> None:
        """task_event to the requester, and the acknowledgement that ends its link's retries."""
        self._reply(msg, "task_event", payload)
        self.endpoint.send(ack_for(msg, self.endpoint.name))

    def _robot_msg(self, msg: Message) -> RobotInfo | None:
        name = msg.payload.get("robot")
        if not isinstance(name, str) or name not in self.robots:
            return None
        if msg.source in self.robots and msg.source != name:
            return None  # a robot speaks only for itself
        return self.robots[name]

    def _on_task_started(self, msg: Message) -> None:
        robot = self._robot_msg(msg)
        task = self.tasks.get(str(msg.payload.get("task_id")))
        if robot is None or task is None:
            return
        if task.robot != robot.name or task.final:
            self._send_cancel(robot.name, task.id, "this task is not yours any more")
            return
        if task.state is TaskState.ASSIGNED:
            task.move(TaskState.RUNNING)
            self._unconfirmed.discard(task.id)
            self._changed(task, "started")

    def _on_task_ended(self, msg: Message) -> None:
        robot = self._robot_msg(msg)
        task = self.tasks.get(str(msg.payload.get("task_id")))
        if robot is None or task is None or task.robot != robot.name or task.final:
            return
        outcome = msg.payload.get("outcome", "done")
        state = {"done": TaskState.DONE, "failed": TaskState.FAILED}.get(
            outcome, TaskState.CANCELLED
        )
        reason = str(msg.payload.get("reason") or "").strip()
        if state is TaskState.FAILED and not reason:
            reason = f"{robot.name} reported the task failed without saying why"
        task.move(state, reason=reason)
        if robot.current == task.id:
            self._set_current(robot, None)
        if task.kind == "charge" and state is TaskState.DONE:
            robot.needs_charge = False
        if task.kind == "go_to" and state is TaskState.DONE:
            # The robot is where it was sent; its next robot_state may come a second later
            # and the idle policy must not send it there again meanwhile.
            target = task.params.get("node")
            if isinstance(target, str) and target in self.graph:
                robot.node = target
        if state is TaskState.DONE and task.started_at and not task.internal:
            took = time.time() - task.started_at
            self._durations[task.kind] = 0.8 * self._durations[task.kind] + 0.2 * took
        if state is TaskState.DONE and task.started_at:
            self.estimator.ended(task, time.time() - task.started_at)
        self._changed(task, state.value)
        self.dispatch()

    def _on_tour_progress(self, msg: Message) -> None:
        """A point reached or explained: into the task's history, refined estimate to all."""
        robot = self._robot_msg(msg)
        task = self.tasks.get(str(msg.payload.get("task_id")))
        if robot is None or task is None or task.robot != robot.name or task.final:
            return
        try:
            p = msg.payload_as(TourProgress)
        except ValidationError:
            return
        self.estimator.progress(task, p.index, p.stage, p.poi)
        if self.store is not None:
            self.store.record(task, f"point {p.index}/{p.total} {p.stage}")
        self.endpoint.publish("task_event", self._event_payload(task))

    def _on_robot_state(self, msg: Message) -> None:
        robot = self._robot_msg(msg)
        if robot is None:
            return
        p = msg.payload
        if p.get("mode") == "offline":
            self._robot_lost(robot)
            return
        came_back = returned = not robot.online
        robot.online = True
        robot.offline_since = None
        robot.last_seen = self.clock()
        robot.mode = str(p.get("mode", "idle"))
        moved = False
        if isinstance(p.get("node"), str) and p["node"] in self.graph:
            moved = robot.node != p["node"]
            robot.node = p["node"]
        # A robot that does not know its floor yet (no site on board) is on its node's floor.
        robot.floor = p.get("floor") or self.graph.floor_of.get(robot.node or "") or robot.floor
        battery = p.get("battery")
        if isinstance(battery, int | float) and 0 <= battery <= 1:
            robot.battery = float(battery)
            if robot.needs_charge and robot.battery >= 0.95:
                robot.needs_charge = False
                came_back = True  # available again: worth a dispatch
        reported = p.get("task_id") or None
        robot.reported_task = reported
        before = robot.current
        was_fault = robot.fault
        robot.fault = robot.mode == "fault"
        self._reconcile(robot, reported)
        current = self.tasks.get(robot.current) if robot.current else None
        if returned and current is not None and current.state is TaskState.ASSIGNED:
            if reported != current.id:
                # Its link went before it acknowledged task_assigned (retries stop when a
                # robot is gone): now it is back, it gets the task again.
                log.info("%s is back without task %s: sent again", robot.name, current.id)
                self._send_assigned(current, robot)
        if robot.fault and not was_fault and robot.current is not None:
            self._requeue(self.tasks[robot.current], "robot fault")
        # robot_state comes at a steady rate from every robot: re-plan only on news.
        released = robot.current is None and before is not None
        if came_back or was_fault != robot.fault or released or (robot.current is None and moved):
            self.dispatch()

    def _reconcile(self, robot: RobotInfo, reported: str | None) -> None:
        """Match what the robot says it runs with what we gave it."""
        ours = self.tasks.get(robot.current) if robot.current else None
        if reported is not None and (ours is None or ours.id != reported):
            task = self.tasks.get(reported)
            if task is None or task.robot != robot.name or task.final:
                self._send_cancel(robot.name, reported, "not assigned to you")
        if ours is None or ours.final:
            return
        if reported == ours.id:
            if ours.state is TaskState.ASSIGNED:
                ours.move(TaskState.RUNNING, reason="reported by the robot")
                self._changed(ours, "started")
            self._unconfirmed.discard(ours.id)
        elif ours.id in self._unconfirmed:
            # Restarted server (or robot back from a long absence): it no longer runs it.
            self._unconfirmed.discard(ours.id)
            self._requeue(ours, "the robot no longer runs it")
        elif ours.state is TaskState.RUNNING:
            # It started it (task_started came first on the same link) and now runs something
            # else or nothing: its agent restarted. Without this the task stayed `running`
            # for ever on a robot back in seconds (found by the soak).
            self._requeue(ours, "the robot no longer runs it (its agent restarted)")

    def _on_battery_low(self, msg: Message) -> None:
        robot = self._robot_msg(msg)
        if robot is None:
            return
        robot.needs_charge = True
        current = self.tasks.get(robot.current) if robot.current else None
        if current is not None and current.internal and current.kind != "charge":
            self._send_cancel(robot.name, current.id, "battery low")
            current.move(TaskState.CANCELLED, reason="battery low")
            self._set_current(robot, None)
            self._changed(current, "cancelled")
        self.dispatch()

    def _on_battery_panic(self, msg: Message) -> None:
        robot = self._robot_msg(msg)
        if robot is None:
            return
        robot.needs_charge = True
        current = self.tasks.get(robot.current) if robot.current else None
        if current is not None and current.kind != "charge":
            if current.internal:
                self._send_cancel(robot.name, current.id, "battery panic")
                current.move(TaskState.CANCELLED, reason="battery panic")
                self._set_current(robot, None)
                self._changed(current, "cancelled")
            else:
                self._rather_not.setdefault(current.id, set()).add(robot.name)
                self._requeue(current, "battery panic")
        self.dispatch()

    def _on_robot_disconnected(self, msg: Message) -> None:
        name = msg.payload.get("robot") or msg.payload.get("name")
        if isinstance(name, str) and name in self.robots:
            self._robot_lost(self.robots[name])

    def _robot_lost(self, robot: RobotInfo) -> None:
        """Off the network: it may still be running its task; after ``lost_grace_s`` the task
        goes to another robot."""
        if robot.online:
            robot.online = False
            robot.mode = "offline"
            robot.offline_since = self.clock()
            self.dispatch()

    # --- watchdog ------------------------------------------------------------------------
    async def _watch(self) -> None:
        assert self.tick_s is not None
        while True:
            await asyncio.sleep(self.tick_s)
            try:
                self.check_timeouts()
            except Exception:
                log.exception("task manager watchdog failed")

    def check_timeouts(self) -> None:
        now = self.clock()
        for robot in self.robots.values():
            if robot.online and robot.last_seen is not None:
                if now - robot.last_seen > self.robot_timeout_s:
                    self._robot_lost(robot)
            if not robot.online and robot.current is not None:
                since = robot.offline_since if robot.offline_since is not None else now
                if robot.offline_since is None:
                    robot.offline_since = now
                if now - since > self.lost_grace_s:
                    lost = self.tasks[robot.current]
                    self._rather_not.setdefault(lost.id, set()).add(robot.name)
                    self._requeue(lost, "robot lost")
        for task_id, at in list(self._assigned_at.items()):
            task = self.tasks.get(task_id)
            if task is None or task.state is not TaskState.ASSIGNED:
                self._assigned_at.pop(task_id, None)
                continue
            holder = self.robots.get(task.robot or "")
            if holder is not None and holder.online and now - at > self.start_timeout_s:
                if task.internal:
                    task.move(TaskState.FAILED, reason="the robot did not start it")
                    self._set_current(holder, None)
                    self._changed(task, "failed")
                else:
                    self._requeue(task, "the robot did not start it")
        self.dispatch()

    # --- helpers -------------------------------------------------------------------------
    def _requeue(self, task: Task, reason: str) -> None:
        """Back to the queue in its old place (same priority and arrival order)."""
        if task.internal:
            self._leave_robot(task, reason)
            task.move(TaskState.CANCELLED, reason=reason)
            self._changed(task, "cancelled")
            return
        self._leave_robot(task, reason)
        try:
            self._target_node(task.kind, task.params)
        except TaskError as exc:  # the site changed under it: nothing to go back to
            task.move(TaskState.CANCELLED, reason=f"{reason}; the site changed: {exc}")
            self._changed(task, "cancelled")
            return
        task.robot = None
        task.move(TaskState.QUEUED, reason=reason)
        self.queue.push(task)
        self._changed(task, "requeued")

    def _leave_robot(self, task: Task, reason: str) -> None:
        if task.robot is None:
            return
        robot = self.robots.get(task.robot)
        if task.state in (TaskState.ASSIGNED, TaskState.RUNNING):
            self._send_cancel(task.robot, task.id, reason)
        if robot is not None and robot.current == task.id:
            self._set_current(robot, None)
        self._assigned_at.pop(task.id, None)
        self._unconfirmed.discard(task.id)

    def _reply(self, msg: Message, type_: str, payload: dict[str, Any]) -> None:
        self.endpoint.send(msg.reply(type_, payload))

    def _set_current(self, robot: RobotInfo, task_id: str | None) -> None:
        robot.current = task_id
        task = self.tasks.get(task_id) if task_id is not None else None
        if task is None or task.internal:
            self._idle.add(robot.name)
        else:
            self._idle.discard(robot.name)

    def _send_cancel(self, robot: str, task_id: str, reason: str) -> None:
        # Replaces an unacknowledged task_assigned of this task (same key): the robot gets the
        # cancel, never a late copy of the assignment after it.
        cancel = Message(
            type="task_cancel",
            source=self.endpoint.name,
            destination=robot,
            payload={"task_id": task_id, "reason": reason},
        )
        self.courier.post(cancel, key=("task", task_id, robot))

    def _target_node(self, kind: str, params: dict[str, Any]) -> str:
        """Where a task starts (for path cost); raises TaskError if params do not fit."""
        spec = KINDS.get(kind)
        if spec is None:
            raise InvalidTask(f"unknown task kind {kind!r} (expected one of {sorted(NETS)})")
        try:
            return spec.target(self.site, params, self.graph)
        except UnknownTarget as exc:
            raise InvalidTask(str(exc)) from None

    def _net_params(self, task: Task) -> dict[str, Any]:
        """Everything the robot's net needs, so it never asks back."""
        site, p = self.site, task.params
        lang = resolve_language(site, p.get("lang"))
        if task.kind == "tour":
            tour = site.tour(p["tour"])
            assert tour is not None
            pois = [q for q in (site.poi(i) for i in tour.points) if q is not None]
            points = [
                {"poi": q.id, "node": q.node, "index": i, "total": len(pois)}
                | poi_texts(site, q, lang)
                for i, q in enumerate(pois, start=1)
            ]
            return {"tour": tour.id, "points": points, "lang": lang}
        if task.kind == "go_to_poi":
            poi = site.poi(p["poi"])
            assert poi is not None
            texts = poi_texts(site, poi, lang)
            return {"poi": poi.id, "node": poi.node, "text": texts["text"], "lang": texts["lang"]}
        if task.kind == "charge":
            station = p.get("station") or site.charging_stations[0].id
            node = next(s.node for s in site.charging_stations if s.id == station)
            return {"station": station, "node": node}
        return {"node": p["node"]}

    def _event_payload(self, task: Task) -> dict[str, Any]:
        return {
            "task_id": task.id,
            "state": task.state.value,
            "robot": task.robot,
            "queue_position": self.queue_position(task),
            **self.estimator.estimate(task).as_dict(),
            "progress": self.estimator.progress_view(task),
            "reason": task.reason,
        }

    def _changed(self, task: Task, event: str) -> None:
        """Every state change: an event on the hub and a row in the task's history."""
        self.estimator.changed(task, event)
        if self.store is not None:
            self.store.record(task, event)
        self.endpoint.publish("task_event", self._event_payload(task))
        if task.state in FINAL_STATES:
            self._avoid.pop(task.id, None)
            self._rather_not.pop(task.id, None)
            self._finished.append(task.id)
            if len(self._finished) > MAX_FINISHED_IN_MEMORY:
                old = self._finished.pop(0)
                if old in self.tasks and self.tasks[old].final:
                    del self.tasks[old]
