"""The console feed: turns what the managers do into hub messages a page can follow.

- ``lock_changed``: an area lock's view whenever it changes (the Traffic Manager sends grants to
  robots only; staff need every change). Diffed after each message that may change a lock,
  at most once per event-loop turn.
- ``event_logged``: every row written to the event log, as it is written.
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

from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.console import EventLogged, LockChanged
from guidebot.payloads.petri import PetriNetEvent
from guidebot.payloads.tasks import RobotLink
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
    paused_at: str | None = None
    """The transition a breakpoint holds it before (the net editor's debugger)."""

    def as_dict(self) -> dict[str, Any]:
        return {
            "target": self.target,
            "instance_id": self.instance_id,
            "net": self.net,
            "started": self.started,
            "marking": dict(self.marking),
            "firings": [{"transition": t, "time": at} for t, at in self.firings],
            "paused_at": self.paused_at,
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
        robots: Callable[[], set[str]],
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.locks = locks
        self.robots = robots
        self.lock_views: dict[str, dict[str, Any]] = {}
        self.nets: dict[tuple[str, str], RunningNet] = {}
        self._diff_scheduled = False

    async def on_start(self) -> None:
        self.lock_views = {v.area: lock_dict(v) for v in self.locks.lock_views()}
        ep = self.endpoint
        self.on(ep, RobotLink, self._on_robot_disconnected, types=["robot_disconnected"], tap=True)
        self.on(ep, PetriNetEvent, self._on_net_event, tap=True)
        for pattern in LOCK_TRIGGERS:
            self.subscribe(ep, pattern, self._on_lock_trigger, tap=True)

    def _on_lock_trigger(self, message: Message) -> None:
        self.schedule_lock_diff()

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

    # --- robots -----------------------------------------------------------------------
    def _on_robot_disconnected(self, message: Message, link: RobotLink) -> None:
        robot = link.robot or message.source
        for key in [k for k in self.nets if k[0] == robot]:
            del self.nets[key]

    # --- Petri nets -----------------------------------------------------------------------
    def _on_net_event(self, message: Message, event: PetriNetEvent) -> None:
        target = message.source or "rgm"
        key = (target, event.instance_id)
        if event.kind == "ended":
            self.nets.pop(key, None)
            return
        net = self.nets.get(key)
        if net is None:
            net = RunningNet(target, key[1], event.net, time.time())
            self.nets[key] = net
        net.marking.update(event.marking)
        if event.kind == "fired" and event.transition:
            net.firings.append((event.transition, event.time))
        net.paused_at = event.transition if event.kind == "paused" else None

    def running_nets(self, target: str) -> list[dict[str, Any]]:
        return [n.as_dict() for (t, _), n in self.nets.items() if t == target]


def relay_events(endpoint: Endpoint) -> Callable[[dict[str, Any]], None]:
    """A DbStore listener that publishes each event-log row as ``event_logged``."""

    def listener(row: dict[str, Any]) -> None:
        endpoint.publish(EventLogged(**row))

    return listener
