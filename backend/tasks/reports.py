"""A robot's reports on its task: ``task_started``, ``task_ended``, ``tour_progress``.

A robot speaks only for itself and only about the task it holds; a report about a task taken
from it gets that task cancelled on the robot again (docs/server.md, "Task Manager").
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

from backend.tasks.desk import Desk
from backend.tasks.handover import arrived
from backend.tasks.model import Task, TaskError, TaskState
from backend.tasks.robots import RobotInfo
from backend.tasks.trouble import TroubleWaits
from guidebot.delivery import Courier
from guidebot.messages import Message
from guidebot.payloads.robot import ENDED_REPORTED, EndedTask
from guidebot.payloads.tasks import TaskEnded, TaskStarted, TourProgress
from guidebot.site.graph import SiteGraph

if TYPE_CHECKING:
    from backend.tasks.eta import EtaEstimator
    from backend.tasks.manager import TaskStore

__all__ = ["TaskReports"]

log = logging.getLogger(__name__)

_ENDED = {"done": TaskState.DONE, "failed": TaskState.FAILED}
"""A task_ended outcome -> the task's final state (anything else: cancelled)."""
ERRANDS = frozenset({"charge", "go_to"})
"""The kinds of an idle robot's errands (backend/tasks/choice.py, ``idle_errands``)."""
BROKE = re.compile(r"\bbase fault\b")
"""A failure reason that says the robot broke, not the task: its task goes to another robot."""


class ReportsDesk(Desk, Protocol):
    """What the report handlers need of the manager beyond ``Desk``."""

    graph: SiteGraph
    estimator: EtaEstimator
    courier: Courier
    store: TaskStore | None
    trouble: TroubleWaits

    def closed_now(self) -> Mapping[str, object]: ...
    def target_of(self, kind: str, params: dict[str, Any]) -> str: ...
    def publish_event(self, task: Task) -> None: ...
    def errand_failed(self, robot: RobotInfo, task: Task, trouble: bool = False) -> None: ...
    def errand_done(self, robot: RobotInfo, where: str) -> None: ...


class TaskReports:
    """The Task Manager's handlers of what robots say about their tasks."""

    def __init__(self, manager: ReportsDesk) -> None:
        self.tm = manager

    def on_task_started(self, msg: Message, started: TaskStarted) -> None:
        tm = self.tm
        robot = tm.robot_of(msg, started.robot)
        task = tm.book.tasks.get(started.task_id)
        if robot is None or task is None:
            return
        if task.robot != robot.name or task.final:
            tm.send_cancel(robot.name, task.id, "this task is not yours any more")
            return
        # The robot has the assignment: stop resending it (its ack may still be on its way; a
        # resend arriving after the task ended would only be answered again).
        tm.courier.withdraw(("task", task.id, robot.name))
        if task.state is TaskState.ASSIGNED:
            task.move(TaskState.RUNNING)
            tm.book.started(task.id)
            tm.changed(task, "started")

    def on_task_ended(self, msg: Message, ended: TaskEnded) -> None:
        tm = self.tm
        robot = tm.robot_of(msg, ended.robot)
        task = tm.book.tasks.get(ended.task_id)
        if robot is None or task is None or task.robot != robot.name:
            return
        tm.courier.withdraw(("task", task.id, robot.name))
        if task.final:
            return
        if ended.outcome == "refused":
            self._refused(robot, task, ended.reason or "busy")
            return
        self.end(robot, task, ended.outcome, ended.reason, ended.trouble)

    def end(
        self, robot: RobotInfo, task: Task, outcome: str, reason: str, trouble: bool = False
    ) -> None:
        """``robot`` ended ``task`` (not final, its own) with ``outcome``: from its task_ended,
        or from the ``ended`` list of its robot_state when that task_ended was lost;
        ``trouble``: their flag (the failure is a way trouble alone cut off)."""
        tm = self.tm
        state = _ENDED.get(outcome, TaskState.CANCELLED)
        reason = reason.strip()
        if state is TaskState.FAILED and not reason:
            reason = f"{robot.name} reported the task failed without saying why"
        if state is TaskState.FAILED and not task.internal and BROKE.search(reason):
            # The robot broke (a motor lost, a base fault), not the visit: another robot
            # takes it up, a tour from the visitor's stop (backend/tasks/handover.py).
            # Never back to it: its own report of this failure (robot_state ``ended``) would
            # end the task again each time (the soak saw 58 000 requeues in a loop).
            tm.book.avoid(task.id, robot.name)
            tm.requeue(task, f"{robot.name} broke down: {reason}")
            tm.dispatch()
            return
        if (
            state is TaskState.FAILED
            and not task.internal
            and self._waits_for_trouble(robot, task, reason, trouble)
        ):
            return
        task.move(state, reason=reason)
        tm.book.withdraw(task)
        if task.internal and task.kind in ERRANDS:
            if state is TaskState.FAILED:
                tm.errand_failed(robot, task, trouble)  # not made again at once (blocked.py)
            elif state is TaskState.DONE:
                tm.errand_done(robot, f"{task.kind} {task.id}")
        if task.kind == "charge" and state is TaskState.DONE:
            robot.needs_charge = False
        if task.kind == "go_to" and state is TaskState.DONE:
            # The robot is where it was sent; its next robot_state may come a second later
            # and the idle policy must not send it there again meanwhile.
            target = task.params.get("node")
            if isinstance(target, str) and target in tm.graph:
                robot.node = target
        if state is TaskState.DONE and task.started_at:
            tm.estimator.ended(task, time.time() - task.started_at)
        tm.changed(task, state.value)
        tm.dispatch()

    def _waits_for_trouble(self, robot: RobotInfo, task: Task, reason: str, trouble: bool) -> bool:
        """A visitor's task that failed because only trouble (a jammed door, a stuck lift)
        cuts its way off goes back to the queue until the trouble lifts (trouble.py). The
        robot says so with task_ended's typed ``trouble`` flag (its navigation_failed's; the
        reason is words for people, never parsed): a failure of another cause stands, whatever
        is closed meanwhile (an older robot sends no flag: its failures stand). The flag is a
        pre-filter: the map must also show trouble alone cutting the goal off from the robot
        (the trouble may have lifted, or staff closed the way since)."""
        if not trouble:
            return False
        tm = self.tm
        closed = tm.closed_now()
        try:
            goal = tm.target_of(task.kind, task.params)
        except TaskError:
            return False
        cut = tm.trouble.cut_by_trouble(tm.graph, robot.node, goal, closed)
        if cut is None or not tm.trouble.wait(task.id, cut):
            return False
        what = "; ".join(c.what() for c in cut.closures)
        log.info("%s: task %s waits for %s to work again: %s", robot.name, task.id, what, reason)
        tm.requeue(task, f"waiting for {what} to work again ({reason})")
        tm.dispatch()
        return True

    def ended_in_state(self, robot: RobotInfo, ended: Sequence[EndedTask]) -> None:
        """The tasks a robot_state says ended: one still the robot's here ends as if its
        task_ended had come (docs/server.md, "After a restart")."""
        tm = self.tm
        for item in ended[:ENDED_REPORTED]:
            task = tm.book.tasks.get(item.task_id)
            if task is None or task.final or task.robot != robot.name:
                continue
            log.info("%s: task %s ended by the robot's own state", robot.name, task.id)
            tm.courier.withdraw(("task", task.id, robot.name))
            self.end(robot, task, item.outcome, item.reason, item.trouble)

    def _refused(self, robot: RobotInfo, task: Task, reason: str) -> None:
        """Back to the queue, another robot preferred; this one waits for its next robot_state
        (which reconciles what it runs) before it gets a task again."""
        tm = self.tm
        robot.refused = True
        tm.book.rather_not(task.id, robot.name)
        tm.requeue(task, f"{robot.name} refused it: {reason}")
        tm.dispatch()

    def point_shown(self, task: Task, poi: str) -> None:
        """A visit's robot shows its point (robot_state ``poi``): its visitor is told the
        robot is there, and the history says when."""
        tm = self.tm
        if not tm.estimator.point_shown(task, poi):
            return
        if tm.store is not None:
            tm.store.record(task, "point 1/1 arrived", at=time.time())
        tm.publish_event(task)

    def on_tour_progress(self, msg: Message, p: TourProgress) -> None:
        """A point reached, explained or skipped: into the task's history, refined estimate to
        all (a skipped point's reason goes to the visitor in the task's progress)."""
        tm = self.tm
        robot = tm.robot_of(msg, p.robot)
        task = tm.book.tasks.get(p.task_id)
        if robot is None or task is None or task.robot != robot.name or task.final:
            return
        tm.estimator.progress(task, p.index, p.stage, p.poi, p.reason)
        if tm.store is not None:
            detail = {"index": p.index, "total": p.total, "poi": p.poi, "stage": p.stage}
            # its own time: a point leaves the task's updated_at (its last state change) alone
            now = time.time()
            tm.store.record(task, f"point {p.index}/{p.total} {p.stage}", detail, at=now)
        if arrived(task, p.index, p.stage) and tm.store is not None and task.handover:
            stop = f"handover: {robot.name} at the visitor's stop {p.index}"
            tm.store.record(task, stop, at=time.time())
        tm.publish_event(task)
