"""The Task Manager's clock: robots silent too long are lost, a lost robot's task goes to
another robot after the grace period, and a task nobody started is taken back (docs/server.md,
"Robot loss" and "Assignment")."""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from backend.tasks.model import TaskState

if TYPE_CHECKING:
    from backend.tasks.manager import TaskManager

__all__ = ["Watchdog"]

log = logging.getLogger(__name__)


class Watchdog:
    """``check`` runs every ``tick_s`` (``run``), or whenever a test driving the clock says."""

    def __init__(self, manager: TaskManager) -> None:
        self.tm = manager

    async def run(self, tick_s: float) -> None:
        while True:
            await asyncio.sleep(tick_s)
            try:
                self.check()
            except Exception:
                log.exception("task manager watchdog failed")

    def check(self) -> None:
        tm = self.tm
        now = tm.clock()
        for robot in tm.robots.values():
            if robot.online and robot.last_seen is not None:
                if now - robot.last_seen > tm.robot_timeout_s:
                    tm.presence.lost(robot)
            if not robot.online and robot.current is not None:
                since = robot.offline_since if robot.offline_since is not None else now
                if robot.offline_since is None:
                    robot.offline_since = now
                if now - since > tm.lost_grace_s:
                    lost = tm.tasks[robot.current]
                    tm.rather_not.setdefault(lost.id, set()).add(robot.name)
                    tm.requeue(lost, "robot lost")
        for task_id, at in list(tm.assigned_at.items()):
            task = tm.tasks.get(task_id)
            if task is None or task.state is not TaskState.ASSIGNED:
                tm.assigned_at.pop(task_id, None)
                continue
            holder = tm.robots.get(task.robot or "")
            if holder is not None and holder.online and now - at > tm.start_timeout_s:
                if task.internal:
                    task.move(TaskState.FAILED, reason="the robot did not start it")
                    tm.set_current(holder, None)
                    tm.changed(task, "failed")
                else:
                    tm.requeue(task, "the robot did not start it")
        tm.dispatch()
        tm.news.check()
