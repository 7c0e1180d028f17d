"""The robot's side of the reaction chain: from task_assigned to the first moving CAN frame.

A tap on the on-board bus stamps, for the current main task, the paper's T9 (the link got
task_assigned), T10 (RG dispatch asked to run the net), the get_path round trip (T10-T11; zero
when the robot planned on board and only declared its path), T13
(navigation's first non-zero set_velocity) and T14 (that command's velocity frame is on the
CAN bus), then sends them once as ``task_reaction`` for the server's metrics and the reaction
benchmark (docs/reaction.md). Stamps are time.time(): comparable with the server's on one
machine, offset by the clocks' difference across machines.

T14: the RoboCAN base entity sends its velocity frames inline, inside the publish of
set_velocity; this tap runs in the same publish, so its stamp is within microseconds of
python-can's ``send`` (tests/robot/test_reaction.py checks it against a CAN listener).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.tasks import TaskReaction
from guidebot.service import Service

__all__ = ["ReactionTracker"]


class ReactionTracker(Service):
    """Stamps one main task at a time; publishes ``task_reaction`` when the robot moves."""

    def __init__(self, endpoint: Endpoint, robot: str) -> None:
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.sent = 0
        self._stamps: dict[str, Any] | None = None
        self._instance = ""
        self._path_request: str | None = None
        self._velocity_unsub: Callable[[], None] | None = None

    async def on_start(self) -> None:
        """Start before the task runner: this tap must see task_assigned first (the runner's
        handler starts the net, which asks for the path, inside that same publish)."""
        # Taps: path replies and velocity commands are addressed to other endpoints.
        self.subscribe_all(
            self.ep,
            {
                "task_assigned": self._on_assigned,
                "run_petri_net": self._on_run,
                "get_path": self._on_get_path,
                "path": self._on_path,
                "task_cancel": self._on_cancel,
            },
            tap=True,
        )
        self.on_cleanup(self._drop_velocity_tap)

    def _drop_velocity_tap(self) -> None:
        if self._velocity_unsub is not None:
            self._velocity_unsub()
        self._velocity_unsub = None

    def _on_assigned(self, message: Message) -> None:
        p = message.payload
        if p.get("robot") not in (None, self.robot) or not p.get("task_id"):
            return
        task_id = str(p["task_id"])
        self._stamps = {"task_id": task_id, "robot": self.robot, "received_at": time.time()}
        self._instance = f"{self.robot}-task-{task_id}"
        self._path_request = None
        # Subscribed anew for each task, so this handler comes after the base entity's (which
        # subscribes when its module is found): T14 is then stamped after the frame was sent.
        if self._velocity_unsub is not None:
            self._velocity_unsub()
        self._velocity_unsub = self.ep.subscribe("set_velocity", self._on_velocity, tap=True)

    def _on_run(self, message: Message) -> None:
        s = self._stamps
        if s is not None and message.payload.get("instance_id") == self._instance:
            s.setdefault("net_started_at", message.timestamp)

    def _on_get_path(self, message: Message) -> None:
        s = self._stamps
        if s is not None and self._path_request is None:
            s["path_requested_at"] = message.timestamp
            self._path_request = message.id

    def _on_path(self, message: Message) -> None:
        s = self._stamps
        if s is not None and "path_received_at" not in s:
            if self._path_request is not None and message.correlation_id == self._path_request:
                s["path_received_at"] = time.time()

    def _on_velocity(self, message: Message) -> None:
        s = self._stamps
        if s is None or "path_requested_at" not in s:
            return
        if not (message.payload.get("v") or message.payload.get("w")):
            return
        # Moving before the answer: navigation planned on board and only told the Traffic
        # Manager (navigation.plan_on_board); the path was in hand when it was declared.
        s.setdefault("path_received_at", s["path_requested_at"])
        moving_at = time.time()
        self._stamps = None
        s["commanded_at"] = message.timestamp
        s["moving_at"] = moving_at
        self.sent += 1
        self.ep.publish(TaskReaction(**s))

    def _on_cancel(self, message: Message) -> None:
        s = self._stamps
        if s is not None and message.payload.get("task_id") == s["task_id"]:
            self._stamps = None
