"""The robot's state report: pose, floor, battery, task, running nets, module health.

Published on the on-board bus as robot_state at a steady rate (the link forwards it to the
hub) and on demand (``publish_now``) after a reconnect so the server resynchronises at once.
"""

from __future__ import annotations

import asyncio
import secrets
from collections.abc import Callable
from typing import Any

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.robot import ENDED_REPORTED, RobotMode, RobotState
from guidebot.service import Service
from robot_agent.battery import BatteryMonitor
from robot_agent.navigation import Navigator
from robot_agent.tasks import TaskRunner

__all__ = ["StateReporter"]


class StateReporter(Service):
    def __init__(
        self,
        endpoint: BusEndpoint,
        robot: str,
        navigator: Navigator,
        battery: BatteryMonitor,
        tasks: TaskRunner,
        *,
        nets: Callable[[], list[str]] | None = None,
        period_s: float = 1.0,
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.nav = navigator
        self.battery = battery
        self.tasks = tasks
        self.nets = nets or (lambda: sorted(set(tasks.running_nets.values())))
        self.period_s = period_s
        self.modules: dict[str, str] = {}
        self.poi: tuple[str | None, str] | None = None
        """(task id, point) of the last show_point: the tour's current step."""
        self.seq = 0
        self.boot_id = secrets.token_hex(8)
        """Drawn once per agent process (robot_state ``boot_id``): the server tells a restart
        from a reconnect by it and drops the old process's holds."""

    async def on_start(self) -> None:
        self.subscribe(self.ep, "module_status", self._on_module_status)
        self.subscribe(self.ep, "show_point", self._on_show_point)
        # A fault is told at once: the server must not hand a broken robot more work
        # in the meantime (it did, a task every few ms, until the next periodic state).
        self.subscribe(self.ep, "robot_fault", self._on_fault)
        self.spawn(self._run(), name="robot-state")

    def _on_fault(self, _message: Message) -> None:
        self.publish_now()

    def _on_module_status(self, message: Message) -> None:
        p = message.payload
        name = str(p.get("name") or p.get("module_id"))
        self.modules[name] = "ok" if p.get("state") == "online" else "lost"

    def _on_show_point(self, message: Message) -> None:
        self.poi = (self.tasks.task_id, str(message.payload.get("poi")))
        self.publish_now()  # at once: a visit's visitor is told the robot is there

    def mode(self) -> RobotMode:
        if self.nav.fault is not None:
            return RobotMode.FAULT
        if self.tasks.current is not None:
            return RobotMode.BUSY
        if self.battery.docked_at is not None or self.battery.charging:
            return RobotMode.CHARGING
        return RobotMode.IDLE

    def snapshot(self) -> dict[str, Any]:
        """The next robot_state payload (advances ``seq``)."""
        self.seq += 1
        return self.snapshot_view()

    def snapshot_view(self) -> dict[str, Any]:
        """The state as it is now, for the touch screen (``seq`` unchanged)."""
        level = self.battery.level
        return {
            "robot": self.robot,
            "x": round(self.nav.x, 3),
            "y": round(self.nav.y, 3),
            "theta": round(self.nav.theta, 3),
            "node": self.nav.node,
            "floor": self.nav.floor,
            "battery": 1.0 if level is None else round(min(max(level, 0.0), 1.0), 3),
            "mode": self.mode().value,
            "navigation": self.nav.state.value,
            "task_id": self.tasks.task_id,
            "speed": round(self.nav.speed, 3),
            "nets": self.nets(),
            "modules": dict(self.modules),
            "poi": self.poi[1] if self.poi and self.poi[0] == self.tasks.task_id else None,
            "areas": self.nav.areas_held(),
            "ended": self.ended(),
            "boot_id": self.boot_id,
            "seq": self.seq,
        }

    def ended(self) -> list[dict[str, str | bool]]:
        """The last tasks that ended, newest first (robot_state ``ended``)."""
        last = list(self.tasks.finished)[-ENDED_REPORTED:]
        return [
            {
                "task_id": t.task_id,
                "outcome": t.outcome or "failed",
                "reason": t.reason[:500],
                "trouble": t.trouble,
            }
            for t in reversed(last)
        ]

    def publish_now(self) -> Message:
        return self.ep.publish(RobotState(**self.snapshot()))

    async def _run(self) -> None:
        while True:
            self.publish_now()
            await asyncio.sleep(self.period_s)
