"""The console feed: turns what the managers do into hub messages a page can follow.

- ``lock_changed``: an area lock's view whenever it changes (the Traffic Manager sends grants to
  robots only; staff need every change). Diffed after each message that may change a lock,
  at most once per event-loop turn.
- ``event_logged``: every row written to the event log, as it is written.
- alerts (backend.console.alerts) from robot, building, lock and task messages.
- the running Petri nets of every robot and of the server's RGM, with their latest marking and
  last firings, from ``petri_net_event`` (``running_nets``).
"""

from __future__ import annotations

import asyncio
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from backend.console.alerts import AlertBook
from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.console import EventLogged, LockChanged
from guidebot.service import Service

__all__ = ["ConsoleFeed", "RunningNet"]

LOCK_TRIGGERS = (
    "robot_state",
    "robot_connected",
    "robot_disconnected",
    "request_area",
    "release_area",
    "task_event",
    "task_ended",
)
LAST_FIRINGS = 8


class LockSource(Protocol):
    def lock_views(self) -> list[Any]: ...


@dataclass(slots=True)
class RunningNet:
    target: str
    """The robot name, or "rgm" for the server's dispatch."""
    instance_id: str
    net: str
    started: float
    marking: dict[str, int] = field(default_factory=dict)
    firings: deque[tuple[str, float]] = field(default_factory=lambda: deque(maxlen=LAST_FIRINGS))

    def as_dict(self) -> dict[str, Any]:
        return {
            "target": self.target,
            "instance_id": self.instance_id,
            "net": self.net,
            "started": self.started,
            "marking": dict(self.marking),
            "firings": [{"transition": t, "time": at} for t, at in self.firings],
        }


def lock_dict(view: Any) -> dict[str, Any]:
    return {
        "area": view.area,
        "state": view.state.value,
        "holder": view.holder,
        "since": view.since,
        "entered": view.entered,
        "waiting": list(view.waiting),
    }


class ConsoleFeed(Service):
    def __init__(
        self,
        endpoint: Endpoint,
        locks: LockSource,
        alerts: AlertBook,
        robots: Callable[[], set[str]],
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.locks = locks
        self.alerts = alerts
        self.robots = robots
        self.lock_views: dict[str, dict[str, Any]] = {}
        self.nets: dict[tuple[str, str], RunningNet] = {}
        self._diff_scheduled = False
        self._lost_modules: set[tuple[str, str]] = set()

    async def on_start(self) -> None:
        self.lock_views = {v.area: lock_dict(v) for v in self.locks.lock_views()}
        handlers: dict[str, Callable[[Message], None]] = {
            "robot_state": self._on_robot_state,
            "robot_disconnected": self._on_robot_disconnected,
            "battery_panic": self._on_battery_panic,
            "robot_fault": self._on_robot_fault,
            "command_failed": self._on_command_failed,
            "building_module_health": self._on_module_health,
            "task_event": self._on_task_event,
            "staff_alert": self._on_staff_alert,
            "petri_net_event": self._on_net_event,
        }
        for pattern in {*LOCK_TRIGGERS, *handlers}:
            handler = handlers.get(pattern)
            self.subscribe(self.endpoint, pattern, self._make_handler(pattern, handler), tap=True)

    def _make_handler(
        self, pattern: str, handler: Callable[[Message], None] | None
    ) -> Callable[[Message], None]:
        trigger = pattern in LOCK_TRIGGERS

        def on_message(message: Message) -> None:
            if handler is not None:
                handler(message)
            if trigger:
                self.schedule_lock_diff()

        return on_message

    # --- locks ------------------------------------------------------------------------
    def schedule_lock_diff(self) -> None:
        """Compare the lock views after the managers have handled the current message."""
        if not self._diff_scheduled:
            self._diff_scheduled = True
            asyncio.get_running_loop().call_soon(self.diff_locks)

    def diff_locks(self) -> None:
        self._diff_scheduled = False
        for view in self.locks.lock_views():
            now = lock_dict(view)
            before = self.lock_views.get(view.area)
            if before == now:
                continue
            self.lock_views[view.area] = now
            self.endpoint.publish(LockChanged(**now))
            if now["state"] == "holder_offline" and (before or {}).get("state") != now["state"]:
                self.alerts.raise_(
                    "lock_holder_offline",
                    now["area"],
                    f"area {now['area']} is held by {now['holder']}, which is offline: "
                    "release it by hand once the robot is out of the area",
                )

    # --- alerts -------------------------------------------------------------------------
    def _robot(self, message: Message) -> str:
        return str(message.payload.get("robot") or message.source)

    def _on_robot_state(self, message: Message) -> None:
        modules = message.payload.get("modules")
        if not modules:
            return
        robot = self._robot(message)
        for name, state in modules.items():
            key = (robot, str(name))
            if state == "lost" and key not in self._lost_modules:
                self._lost_modules.add(key)
                self.alerts.raise_(
                    "can_module_lost", f"{robot}/{name}", f"{robot}: CAN module {name} lost"
                )
            elif state != "lost":
                self._lost_modules.discard(key)

    def _on_robot_disconnected(self, message: Message) -> None:
        robot = self._robot(message)
        self.alerts.raise_("robot_lost", robot, f"robot {robot} lost its connection")
        for key in [k for k in self.nets if k[0] == robot]:
            del self.nets[key]

    def _on_battery_panic(self, message: Message) -> None:
        robot = self._robot(message)
        level = float(message.payload.get("level", 0.0))
        self.alerts.raise_("battery_panic", robot, f"{robot}: battery at {level:.0%}")

    def _on_robot_fault(self, message: Message) -> None:
        robot = self._robot(message)
        kind = message.payload.get("kind", "fault")
        detail = message.payload.get("detail", "")
        self.alerts.raise_("robot_fault", f"{robot}/{kind}", f"{robot}: {kind} {detail}".strip())

    def _on_command_failed(self, message: Message) -> None:
        command = str(message.payload.get("command", "command"))
        reason = str(message.payload.get("reason", ""))
        self.alerts.raise_(
            "building_command_failed", f"{command}:{reason[:40]}", f"{command} failed: {reason}"
        )

    def _on_module_health(self, message: Message) -> None:
        module = str(message.payload.get("module"))
        if message.payload.get("online") is False:
            error = message.payload.get("last_error") or "no answer"
            self.alerts.raise_("module_offline", module, f"Modbus module {module}: {error}")

    def _on_task_event(self, message: Message) -> None:
        if message.payload.get("state") == "failed":
            task = str(message.payload.get("task_id"))
            robot = message.payload.get("robot") or "no robot"
            self.alerts.raise_("task_failed", task, f"task {task} failed ({robot})", "warning")

    def _on_staff_alert(self, message: Message) -> None:
        """The Traffic Manager's alerts (backend.alerts): each active one becomes a console
        alert to acknowledge, keyed by area or robot so a condition the console also sees
        (a lock holder offline) shows once."""
        p = message.payload
        if not p.get("active"):
            return
        subject = str(p.get("area") or p.get("robot") or p.get("alert_id"))
        message_ = str(p.get("message"))
        if p.get("severity") == "critical":
            self.alerts.raise_(str(p.get("kind")), subject, message_, "error")
        else:
            self.alerts.raise_(str(p.get("kind")), subject, message_, "warning")

    # --- Petri nets -----------------------------------------------------------------------
    def _on_net_event(self, message: Message) -> None:
        p = message.payload
        target = message.source or "rgm"
        key = (target, str(p.get("instance_id")))
        kind = p.get("kind")
        if kind == "ended":
            self.nets.pop(key, None)
            return
        net = self.nets.get(key)
        if net is None:
            net = RunningNet(target, key[1], str(p.get("net")), time.time())
            self.nets[key] = net
        net.marking.update({str(k): int(v) for k, v in (p.get("marking") or {}).items()})
        if kind == "fired" and p.get("transition"):
            net.firings.append((str(p["transition"]), float(p.get("time") or 0.0)))

    def running_nets(self, target: str) -> list[dict[str, Any]]:
        return [n.as_dict() for (t, _), n in self.nets.items() if t == target]


def relay_events(endpoint: Endpoint) -> Callable[[dict[str, Any]], None]:
    """A DbStore listener that publishes each event-log row as ``event_logged``."""

    def listener(row: dict[str, Any]) -> None:
        endpoint.publish(EventLogged(**row))

    return listener
