"""The shared bus connection and scheduler of one simulated robot's modules.

One connection to the virtual bus (one reader thread, software filtering on *M* + 1 and the
broadcast ID, as each module's own filter would) and one scheduler task. The scheduler sleeps
until the next frame some module owes (watchdog, ENCODER, SONAR, BATTERY) and runs the 50 Hz
physics step only while something moves (a wheel, a servo); a received command wakes it at
once. Periodic frames fall on a grid of their own period (multiples of it on the monotonic
clock), so modules with the same period send in the same wake-up.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from typing import TYPE_CHECKING

import can

from robot_agent.robocan import protocol as p
from robot_agent.robocan.busopen import BusReader, open_bus

if TYPE_CHECKING:
    from robot_agent.robocan.sim.module import SimModule

__all__ = ["DUE_EPS_S", "TICK_S", "SimHost", "next_slot"]

log = logging.getLogger(__name__)

TICK_S = 0.02  # physics step of the simulated firmware while something moves
DUE_EPS_S = 0.001  # a frame due this close to now goes out in this wake-up


def next_slot(due: float, period: float, now: float) -> float:
    """The next send time of a periodic frame that was due at ``due``: one period later, or
    if that is already past (the first frame, a stalled process) the next multiple of the
    period after ``now``. Frames of the same period thus share wake-ups across modules."""
    following = due + period
    if following > now + DUE_EPS_S:
        return following
    return (math.floor(now / period) + 1) * period


class SimHost:
    """One virtual-bus connection and one scheduler for several simulated modules."""

    def __init__(self, bus_spec: str) -> None:
        self.bus_spec = bus_spec
        self.modules: dict[int, SimModule] = {}
        self.wakeups = 0  # scheduler wake-ups (tests, profiling)
        self._bus: can.BusABC | None = None
        self._reader: BusReader | None = None
        self._task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._waiter: asyncio.Future[None] | None = None
        self._poked = False

    @property
    def running(self) -> bool:
        return self._task is not None

    async def start(self) -> None:
        if self._task is not None:
            return
        bus = self._bus = open_bus(self.bus_spec)
        # Slaves listen to M + 1 and the broadcast ID 0x001: odd standard IDs only.
        bus.set_filters([{"can_id": 0x001, "can_mask": 0x001, "extended": False}])
        loop = self._loop = asyncio.get_running_loop()
        self._reader = BusReader(bus, self._on_frames, loop=loop, name="sim-reader")
        self._reader.start()
        self._task = asyncio.create_task(self._run(), name="sim-host")

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is None:
            return
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        if self._reader is not None:
            await asyncio.to_thread(self._reader.stop)
            self._reader = None
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def attach(self, module: SimModule) -> None:
        self.modules[module.module_id] = module
        self.poke()

    def detach(self, module: SimModule) -> None:
        if self.modules.get(module.module_id) is module:
            del self.modules[module.module_id]

    def send(self, can_id: int, data: bytes) -> bool:
        if self._bus is None:
            return False
        msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=False)
        try:
            self._bus.send(msg)
        except can.CanError as exc:
            log.warning("sim 0x%02X: send failed: %s", can_id, exc)
            return False
        return True

    def poke(self) -> None:
        """Something changed (a command, a test hook): recompute the schedule now."""
        self._poked = True
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _on_frames(self, batch: list[can.Message]) -> None:
        for msg in batch:
            can_id = msg.arbitration_id
            if can_id == p.BROADCAST_ID:
                for module in list(self.modules.values()):
                    module._on_can(msg, broadcast=True)
            else:
                addressed = self.modules.get(can_id - 1)
                if addressed is not None:
                    addressed._on_can(msg)
        self.poke()

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            self.wakeups += 1
            self._poked = False
            now = time.monotonic()
            due = math.inf
            active = False
            for module in list(self.modules.values()):
                try:
                    module.tick(now)
                except Exception:
                    log.exception("sim 0x%02X: tick failed", module.module_id)
                due = min(due, module.next_due())
                active = active or module.active
            if active:
                due = min(due, now + TICK_S)
            if self._poked:
                continue
            waiter = self._waiter = loop.create_future()
            timer = None
            if due < math.inf:
                # loop.time() is time.monotonic(); never a past deadline (no busy loop)
                timer = loop.call_at(max(due, now + DUE_EPS_S), _wake, waiter)
            try:
                await waiter
            finally:
                self._waiter = None
                if timer is not None:
                    timer.cancel()


def _wake(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)
