"""Where each robot is and what it says it runs: ``robot_state``, link loss, and the match of
its reported task with the one we gave it after a reconnect or a restart (docs/server.md,
"Robot loss")."""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Protocol

from backend.tasks.battery_forecast import learn_charge
from backend.tasks.charging import learn_drain
from backend.tasks.desk import Desk
from backend.tasks.model import Task, TaskState
from backend.tasks.robots import RobotInfo
from guidebot.messages import Message
from guidebot.payloads.robot import RobotMode, RobotState
from guidebot.payloads.tasks import RobotLink
from guidebot.site.graph import SiteGraph

if TYPE_CHECKING:
    from backend.tasks.eta import EtaEstimator
    from backend.tasks.news import QueueNews
    from backend.tasks.reports import TaskReports

__all__ = ["Presence"]

ON_ITS_WAY = frozenset(
    {"planning", "moving", "waiting_area", "waiting_door", "waiting_elevator", "riding"}
)
"""A robot's navigation states on its way somewhere (a tour's robot leading its visitors on)."""

log = logging.getLogger(__name__)

BLOCKED = frozenset({"door_blocked"})
"""Navigation states of a robot whose way is blocked (robot_state ``navigation``)."""
WAITING = frozenset({"waiting_door", "waiting_area"})
"""Navigation states that are normal for a while: held up once they last ``HELD_UP_AFTER_S``."""
HELD_UP_AFTER_S = 20.0


class PresenceDesk(Desk, Protocol):
    """What presence needs of the manager beyond ``Desk``."""

    graph: SiteGraph
    estimator: EtaEstimator
    news: QueueNews
    report_grace_s: float

    def send_assigned(self, task: Task, robot: RobotInfo) -> None: ...
    def moved_to(self, robot: RobotInfo) -> None: ...
    def publish_event(self, task: Task) -> None: ...


class Presence:
    """The Task Manager's handlers of robot_state and robot_disconnected."""

    def __init__(self, manager: PresenceDesk, reports: TaskReports) -> None:
        self.tm = manager
        self.reports = reports

    def on_robot_state(self, msg: Message, p: RobotState) -> None:
        tm = self.tm
        robot = tm.robot_of(msg, p.robot)
        if robot is None:
            return
        if p.mode is RobotMode.OFFLINE:
            self.lost(robot)
            return
        came_back = returned = not robot.online
        robot.online = True
        robot.offline_since = None
        robot.last_seen = tm.clock()
        robot.seen_at = time.time()
        robot.mode = p.mode.value
        moved = False
        if p.node is not None and p.node in tm.graph:
            moved = robot.node != p.node
            robot.node = p.node
            if moved:
                tm.moved_to(robot)
        self.held_up(robot, p.navigation)
        # A robot that does not know its floor yet (no site on board) is on its node's floor.
        robot.floor = p.floor or tm.graph.floor_of.get(robot.node or "") or robot.floor
        if "battery" in p.model_fields_set:  # a state without it says nothing of the battery
            robot.battery = p.battery
            fleet = tm.book.robots.values()  # rates stand in for a robot that has learned none
            learn_drain(robot, robot.battery, robot.mode, tm.clock(), fleet)
            learn_charge(robot, robot.battery, robot.mode, tm.clock(), fleet)
            if robot.needs_charge and robot.battery >= 0.95:
                robot.needs_charge = False
                came_back = True  # available again: worth a dispatch
        reported = p.task_id or None
        robot.reported_task = reported
        unrefused = robot.refused and reported in (None, robot.current)
        if unrefused:
            robot.refused = False
        before = robot.current
        was_fault = robot.fault
        robot.fault = robot.mode == "fault"
        self.reports.ended_in_state(robot, p.ended)  # before a restored one is requeued
        self.reconcile(robot, reported)
        current = tm.book.current_of(robot)
        if current is not None and p.poi is not None and reported == current.id:
            if current.state is TaskState.RUNNING and current.kind == "tour":
                tm.estimator.seen_at(current, p.poi)  # its stop, after our restart
            elif current.state is TaskState.RUNNING:
                self.reports.point_shown(current, p.poi)  # a visit's robot is at its point
        if current is not None and reported == current.id and p.navigation in ON_ITS_WAY:
            if current.kind == "tour" and tm.estimator.went_on(current):
                tm.publish_event(current)  # its visitors said yes: leading them on
        if returned and current is not None and current.state is TaskState.ASSIGNED:
            if reported != current.id:
                # Its link went before it acknowledged task_assigned (retries stop when a
                # robot is gone): now it is back, it gets the task again.
                log.info("%s is back without task %s: sent again", robot.name, current.id)
                tm.send_assigned(current, robot)
        if robot.fault and not was_fault and robot.current is not None:
            tm.requeue(tm.book.tasks[robot.current], "robot fault")
        # robot_state comes at a steady rate from every robot: re-plan only on news.
        released = robot.current is None and before is not None
        news = came_back or was_fault != robot.fault or released or unrefused
        if news:
            tm.news.changed()
        if news or (robot.current is None and moved):
            tm.dispatch()

    def held_up(self, robot: RobotInfo, navigation: object) -> None:
        """A jam: its way blocked, or waiting for a door or an area too long. The waits told
        to visitors stop promising what it would do (backend/tasks/eta.py)."""
        now = self.tm.clock()
        if navigation in WAITING:
            if robot.waiting_since is None:
                robot.waiting_since = now
        else:
            robot.waiting_since = None
        waited = now - robot.waiting_since if robot.waiting_since is not None else 0.0
        held_up = navigation in BLOCKED or waited >= HELD_UP_AFTER_S
        if held_up != robot.held_up:
            robot.held_up = held_up
            self.tm.news.changed()

    def reconcile(self, robot: RobotInfo, reported: str | None) -> None:
        """Match what the robot says it runs with what we gave it."""
        tm = self.tm
        book = tm.book
        ours = book.current_of(robot)
        if reported is not None and (ours is None or ours.id != reported):
            task = book.tasks.get(reported)
            if task is None or task.robot != robot.name or task.final:
                tm.send_cancel(robot.name, reported, "not assigned to you")
        if ours is None or ours.final:
            return
        if reported == ours.id:
            if ours.state is TaskState.ASSIGNED:
                ours.move(TaskState.RUNNING, reason="reported by the robot")
                tm.changed(ours, "started")
            book.started(ours.id)
        elif (waited := book.unconfirmed_for(ours.id, tm.clock())) is not None:
            # Restarted server or new leader: the robot no longer runs it, or it ended it and
            # its task_ended, sent while no server decided, comes again on the link's back-off,
            # after this robot_state. Requeued once that has had time to come.
            if waited >= tm.report_grace_s:
                tm.requeue(ours, "the robot no longer runs it")
        elif ours.state is TaskState.RUNNING:
            # It started it (task_started came first on the same link) and now runs something
            # else or nothing: its agent restarted. Without this the task stayed `running`
            # for ever on a robot back in seconds (found by the soak).
            tm.requeue(ours, "the robot no longer runs it (its agent restarted)")

    def on_robot_disconnected(self, msg: Message, link: RobotLink) -> None:
        robot = self.tm.book.robots.get(link.robot)
        if robot is not None:
            self.lost(robot)

    def lost(self, robot: RobotInfo) -> None:
        """Off the network: it may still be running its task; after ``lost_grace_s`` the task
        goes to another robot (backend/tasks/watchdog.py)."""
        if robot.online:
            robot.online = False
            robot.mode = "offline"
            robot.offline_since = self.tm.clock()
            self.tm.news.changed()
            self.tm.dispatch()
