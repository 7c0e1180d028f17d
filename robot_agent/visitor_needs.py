"""What a tour's visitor needs of the robot that guides them (docs/accessibility.md), from the
first stop of the task until it ends: a slower tour (``pace: slow``, guidebot/pace.py) drives at
a fraction of the top speed and speaks more slowly; a step-free tour (``step_free``) plans its
legs over no edge with steps (robot_agent/navigation.py), and a stop that only steps lead to is
skipped (the server's path answer says ``steps``). Before the first stop nobody walks with the
robot, so it goes there as usual (the server's estimates count the same way). A step-free visit
to one point (``go_to_poi``) is step-free from its start: its visitor may walk with the robot
from its touch screen."""

from __future__ import annotations

import logging
from typing import Protocol

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.pace import PACES, Pace, pace_of
from guidebot.service import Service
from robot_agent.tasks import TaskRunner

__all__ = ["VisitorNeeds"]

log = logging.getLogger(__name__)


class _Drives(Protocol):
    max_speed: float
    step_free: bool


class _Speaks(Protocol):
    dwell: float


class VisitorNeeds(Service):
    """Sets the navigator's top speed and step-free planning and the speech's dwell to what the
    running task asks for."""

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
        self.step_free = False
        self._task: str | None = None
        """The task whose needs are applied (None: none)."""
        self._early: object = None
        """A point visit whose step-free planning was applied at its assignment."""

    async def on_start(self) -> None:
        self.subscribe_all(
            self.ep,
            {
                "task_assigned": self._on_assigned,
                "show_point": self._on_first_stop,
                "task_ended": self._on_ended,
            },
        )

    def _on_assigned(self, message: Message) -> None:
        """A step-free point visit plans step-free from its first leg (its pace still from
        the point on, as a tour's)."""
        params = message.payload.get("params") or {}
        task_id, current = message.payload.get("task_id"), self.tasks.current
        if current is not None and current.task_id != task_id:
            return  # the robot keeps to the task it runs
        if params.get("step_free") is True and "poi" in params and "tour" not in params:
            self._early = task_id
            self.step_free = self.drive.step_free = True

    def _on_first_stop(self, message: Message) -> None:
        task = self.tasks.current
        if task is None or task.task_id == self._task:
            return
        self._apply(pace_of(task.params), task.params.get("step_free") is True, task.task_id)

    def _on_ended(self, message: Message) -> None:
        ended = message.payload.get("task_id")
        if ended is not None and ended in (self._task, self._early):
            self._early = None
            self._apply(PACES["normal"], False, None)

    def _apply(self, pace: Pace, step_free: bool, task: str | None) -> None:
        if (pace, step_free) != (self.pace, self.step_free):
            log.info("task %s: %s pace, step-free %s", task or self._task, pace.name, step_free)
        self.pace, self.step_free, self._task = pace, step_free, task
        self.drive.max_speed = self.top_speed * pace.speed
        self.drive.step_free = step_free
        self.speech.dwell = pace.dwell
