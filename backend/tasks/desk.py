"""What the Task Manager's parts (presence.py, battery.py, watchdog.py, reports.py) may do
with it: read and change the task book through its operations, and ask the manager for what
touches the hub (events, cancels to robots, dispatch). Each part widens ``Desk`` with the
little more it needs, as ``eta.Fleet`` does for the estimator; TaskManager has them all."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from backend.tasks.book import TaskBook
from backend.tasks.model import Task
from backend.tasks.robots import RobotInfo
from guidebot.messages import Message

__all__ = ["Desk"]


class Desk(Protocol):
    """The manager as its parts see it."""

    @property
    def book(self) -> TaskBook: ...
    @property
    def clock(self) -> Callable[[], float]: ...
    def robot_of(self, msg: Message, name: str) -> RobotInfo | None: ...
    def changed(self, task: Task, event: str) -> None: ...
    def requeue(self, task: Task, reason: str) -> None: ...
    def send_cancel(self, robot: str, task_id: str, reason: str) -> None: ...
    def dispatch(self) -> None: ...
