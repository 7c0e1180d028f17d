"""The Task Manager's clock: robots silent too long are lost, a lost robot's task goes to
another robot after the grace period, and a task nobody started is taken back (docs/server.md,
"Robot loss" and "Assignment")."""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING, Protocol

from backend.tasks.desk import Desk
from backend.tasks.model import TaskState

if TYPE_CHECKING:
    from backend.tasks.news import QueueNews
    from backend.tasks.presence import Presence

__all__ = ["Watchdog"]

log = logging.getLogger(__name__)


class WatchedDesk(Desk, Protocol):
    """What the watchdog needs of the manager beyond ``Desk``: its time-outs and news."""

    robot_timeout_s: float
    lost_grace_s: float
    start_timeout_s: float
    news: QueueNews


class Watchdog:
    """``check`` runs every ``tick_s`` (``run``), or whenever a test driving the clock says."""

    def __init__(self, manager: WatchedDesk, presence: Presence) -> None:
        self.tm = manager
        self.presence = presence

    async def run(self, tick_s: float) -> None:
        while True:
            await asyncio.sleep(tick_s)
            try:
                self.check()
            except Exception:
                log.exception("task manager watchdog failed")

    def check(self) -> None:
        tm = self.tm
        book = tm.book
        now = tm.clock()
        for robot in book.robots.values():
            if robot.online and robot.last_seen is not None:
                if now - robot.last_seen > tm.robot_timeout_s:
                    self.presence.lost(robot)
            if not robot.online and robot.current is not None:
                since = robot.offline_since if robot.offline_since is not None else now
                if robot.offline_since is None:
                    robot.offline_since = now
                if now - since > tm.lost_grace_s:
                    lost = book.tasks[robot.current]
                    book.rather_not(lost.id, robot.name)
                    tm.requeue(lost, "robot lost")
        for task, at in book.unstarted():
            if task.state is not TaskState.ASSIGNED:
                continue  # moved on since the snapshot
            holder = book.robots.get(task.robot or "")
            if holder is not None and holder.online and now - at > tm.start_timeout_s:
                if task.internal:
                    task.move(TaskState.FAILED, reason="the robot did not start it")
                    book.withdraw(task)
                    tm.changed(task, "failed")
                else:
                    tm.requeue(task, "the robot did not start it")
        tm.dispatch()
        tm.news.check()
