"""The task book: who holds what. The tasks, the robots, the queue, and the marks that tie
them together, with the one writer of those marks, so that their rules live in one place:

- a robot holds at most one task (``RobotInfo.current``) and is idle when it holds nothing
  or an internal task;
- a task that leaves its robot (``withdraw``, ``requeue``) takes its marks with it: the time
  it was given (start watchdog), the restored-but-unconfirmed mark, its touring time;
- a finished task drops the robots it avoids or would rather not go back to, and only the
  last ``MAX_FINISHED_IN_MEMORY`` finished tasks stay in memory.

No bus, no site: the Task Manager (backend/tasks/manager.py) tells robots and the hub.
The fields robots report (online, mode, node, battery, fault, needs_charge...) are written
by the handlers of those reports (presence.py, battery.py, reports.py).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Collection, Mapping, Set

from backend.tasks.model import Task, TaskState
from backend.tasks.queue import TaskQueue
from backend.tasks.robots import RobotInfo

__all__ = ["MAX_FINISHED_IN_MEMORY", "TaskBook"]

MAX_FINISHED_IN_MEMORY = 5000


class TaskBook:
    """The Task Manager's state; every change of a robot's task goes through here.
    ``tasks``, ``robots`` and ``queue`` are never replaced (the manager reads them as its own)."""

    def __init__(self, max_queued: int = 100_000, *, wall: Callable[[], float] = time.time) -> None:
        self.tasks: dict[str, Task] = {}
        self.robots: dict[str, RobotInfo] = {}
        self.queue = TaskQueue(max_queued)
        self.wall = wall
        """Unix seconds, for touring time (what a visitor spent on a robot)."""
        self._idle: set[str] = set()
        """Robots free for a main task as far as tasks go: nothing, or an internal task."""
        self._assigned_at: dict[str, float] = {}
        """Task -> when it was assigned (manager's clock), until its robot starts it."""
        self._unconfirmed: dict[str, float | None] = {}
        """Tasks restored after a restart whose robot has not said it still runs them -> when
        the robot first reported without it (None: not yet)."""
        self._avoid: dict[str, set[str]] = {}
        """Task -> robots it must not go to (staff reassigned it away from them)."""
        self._rather_not: dict[str, set[str]] = {}
        """Task -> robots it was taken from (lost, battery panic, refused): used only if no
        other is free."""
        self._on_robot_since: dict[str, float] = {}
        """Visitor task -> when (Unix seconds) its robot was given it: its touring time."""
        self._finished: list[str] = []

    # --- robots ---------------------------------------------------------------------------
    def add_robot(self, robot: RobotInfo) -> None:
        """A robot new on the site: it holds nothing."""
        self.robots[robot.name] = robot
        self._idle.add(robot.name)

    def remove_robot(self, name: str) -> None:
        """A robot gone from the site (its task withdrawn first by the caller)."""
        del self.robots[name]
        self._idle.discard(name)

    @property
    def idle(self) -> Set[str]:
        """Names of the robots free for a main task as far as tasks go."""
        return self._idle

    def current_of(self, robot: RobotInfo) -> Task | None:
        """The task the robot holds (None: none, or one no longer in memory)."""
        return self.tasks.get(robot.current) if robot.current else None

    def set_current(self, robot: RobotInfo, task_id: str | None) -> None:
        """What ``robot`` holds; it stays idle for a main task while that is internal."""
        robot.current = task_id
        task = self.tasks.get(task_id) if task_id is not None else None
        if task is None or task.internal:
            self._idle.add(robot.name)
        else:
            self._idle.discard(robot.name)

    # --- tasks ----------------------------------------------------------------------------
    def add(self, task: Task) -> None:
        """A task the book knows from now on (an internal one, one restored on a robot)."""
        self.tasks[task.id] = task

    def enqueue(self, task: Task) -> None:
        """A queued task (new, restored, or its priority or robot changed): known, and in the
        queue in its place."""
        self.tasks[task.id] = task
        self.queue.push(task)

    def give(self, task: Task, robot: RobotInfo, now: float) -> None:
        """``task`` (moved to assigned) is ``robot``'s now: out of the queue, the start watchdog
        runs from ``now``, a visitor's task counts touring time."""
        self.queue.remove(task.id)
        task.robot = robot.name
        self.set_current(robot, task.id)
        if not task.internal:
            self._on_robot_since[task.id] = self.wall()
        self._assigned_at[task.id] = now
        self._unconfirmed.pop(task.id, None)

    def restored(self, task: Task, robot: RobotInfo, now: float) -> None:
        """After a restart: ``robot`` holds ``task`` again until it says it no longer runs it."""
        self.set_current(robot, task.id)
        self._unconfirmed[task.id] = None
        self._assigned_at[task.id] = now

    def withdraw(self, task: Task) -> None:
        """``task`` leaves the queue or its robot (ended, cancelled, taken away): the robot's
        touring time counts it, the robot holds nothing if it held it, and its marks go."""
        self.queue.remove(task.id)
        self.count_touring(task)
        robot = self.robots.get(task.robot or "")
        if robot is not None and robot.current == task.id:
            self.set_current(robot, None)
        self._assigned_at.pop(task.id, None)
        self._unconfirmed.pop(task.id, None)

    def requeue(self, task: Task, reason: str) -> None:
        """Back to the queue in its old place (same priority and arrival order), on no robot."""
        self.withdraw(task)
        task.robot = None
        task.move(TaskState.QUEUED, reason=reason)
        self.queue.push(task)

    def count_touring(self, task: Task) -> None:
        """``task`` leaves its robot: its time there counts for the robot's turn
        (backend/tasks/choice.py) and its utilisation."""
        since = self._on_robot_since.pop(task.id, None)
        robot = self.robots.get(task.robot or "")
        if since is not None and robot is not None:
            robot.touring_s += max(0.0, self.wall() - since)

    def changed(self, task: Task) -> None:
        """After every change: a finished task forgets its robots, and the oldest finished
        tasks leave memory (the database keeps them)."""
        if not task.final:
            return
        self._avoid.pop(task.id, None)
        self._rather_not.pop(task.id, None)
        self._finished.append(task.id)
        if len(self._finished) > MAX_FINISHED_IN_MEMORY:
            old = self._finished.pop(0)
            if old in self.tasks and self.tasks[old].final:
                del self.tasks[old]

    # --- start and confirmation -------------------------------------------------------------
    def started(self, task_id: str) -> None:
        """Its robot said it runs it: it is no longer unconfirmed."""
        self._unconfirmed.pop(task_id, None)

    def unconfirmed_for(self, task_id: str, now: float) -> float | None:
        """Seconds since the robot first reported without this restored task (0 the first
        time); None if the task is not waiting for its robot's word."""
        if task_id not in self._unconfirmed:
            return None
        since = self._unconfirmed[task_id]
        if since is None:
            self._unconfirmed[task_id] = since = now
        return now - since

    def unstarted(self) -> list[tuple[Task, float]]:
        """Assigned tasks not yet started, with when they were assigned (the start
        watchdog); a task that has moved on is forgotten here."""
        waiting = []
        for task_id, at in list(self._assigned_at.items()):
            task = self.tasks.get(task_id)
            if task is None or task.state is not TaskState.ASSIGNED:
                del self._assigned_at[task_id]
            else:
                waiting.append((task, at))
        return waiting

    # --- where a task may go ------------------------------------------------------------------
    def avoid(self, task_id: str, robot: str) -> None:
        """``task_id`` never goes back to ``robot`` (unless staff name it: ``allow``)."""
        self._avoid.setdefault(task_id, set()).add(robot)

    def allow(self, task_id: str, robot: str) -> None:
        """Staff named ``robot`` for ``task_id``: it is no longer avoided."""
        self._avoid.get(task_id, set()).discard(robot)

    def rather_not(self, task_id: str, robot: str) -> None:
        """``task_id`` was taken from ``robot``: another robot first, if one is free."""
        self._rather_not.setdefault(task_id, set()).add(robot)

    def avoided(self, task_id: str) -> Collection[str]:
        return self._avoid.get(task_id, ())

    def rather_not_robots(self, task_id: str) -> Collection[str]:
        return self._rather_not.get(task_id, ())

    def marks(self, task_id: str) -> Mapping[str, object]:
        """What the book holds about a task beyond the task itself (for tests and logs)."""
        return {
            "assigned_at": self._assigned_at.get(task_id),
            "unconfirmed": task_id in self._unconfirmed,
            "avoid": frozenset(self._avoid.get(task_id, ())),
            "rather_not": frozenset(self._rather_not.get(task_id, ())),
            "touring": task_id in self._on_robot_since,
        }
