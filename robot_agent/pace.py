"""A slower tour on the robot (guidebot/pace.py, docs/accessibility.md): from the first stop of
a task that asks for ``pace: slow`` until it ends, the robot drives at a fraction of its top
speed and speaks more slowly. Before the first stop nobody walks with it, so it goes there at
its usual speed (the server's estimates count the same way)."""

from __future__ import annotations

import logging
from typing import Protocol

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.pace import PACES, Pace, pace_of
from guidebot.service import Service
from robot_agent.tasks import TaskRunner

__all__ = ["PaceKeeper"]

log = logging.getLogger(__name__)


class _Drives(Protocol):
    max_speed: float


class _Speaks(Protocol):
    dwell: float


class PaceKeeper(Service):
    """Sets the navigator's top speed and the speech's dwell to the running task's pace."""

    def __init__(
        self, endpoint: BusEndpoint, tasks: TaskRunner, drive: _Drives, speech: _Speaks
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.tasks = tasks
        self.drive = drive
        self.speech = speech
        self.top_speed = drive.max_speed
        self.pace: Pace = PACES["normal"]
        self._task: str | None = None
        """The task whose pace is applied (None: the normal pace)."""

    async def on_start(self) -> None:
        self.subscribe_all(
            self.ep, {"show_point": self._on_first_stop, "task_ended": self._on_ended}
        )

    def _on_first_stop(self, message: Message) -> None:
        task = self.tasks.current
        if task is None or task.task_id == self._task:
            return
        self._apply(pace_of(task.params), task.task_id)

    def _on_ended(self, message: Message) -> None:
        if self._task is not None and message.payload.get("task_id") == self._task:
            self._apply(PACES["normal"], None)

    def _apply(self, pace: Pace, task: str | None) -> None:
        if pace != self.pace:
            log.info("task %s: %s pace", task or self._task, pace.name)
        self.pace, self._task = pace, task
        self.drive.max_speed = self.top_speed * pace.speed
        self.speech.dwell = pace.dwell
