"""One polling loop per I/O module: fixed-rate sampling, health, reconnect with back-off.

Each module has its own client and its own task, so a slow or dead module never delays
another. Polls are scheduled on a fixed grid (start + n x period): a late wake-up is not carried
over, and slots missed by a slow answer are skipped rather than run in a burst.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

from backend.building._modbus import (
    ModbusIOError,
    ModuleClient,
    ModuleExceptionAnswer,
    ModuleUnreachable,
)
from guidebot.payloads.building import BuildingModuleHealth
from guidebot.service import cancel_and_wait
from guidebot.site.building import BuildingModule, PointKind

__all__ = ["HealthState", "ModuleClient", "ModuleHealth", "ModulePoller", "Sample"]
# ModuleClient: the client class each poller builds, named here so that a bench can swap it
# (bench/plan_modbus.py; mypy's strict no_implicit_reexport).

log = logging.getLogger(__name__)

# kind -> (first address, values); one read per table covers every point of that kind.
Sample = dict[PointKind, tuple[int, list[int]]]

BACKOFF_FIRST_S = 0.1
BACKOFF_MAX_S = 5.0
SLOT_STAMP_MAX_LATE_S = 0.010
JITTER_SAMPLES = 20_000  # ring buffer: the oldest jitter samples are dropped
PHASE_GROUPS = 4
"""Modules start their polls at one of this many phases of the period. Each wake-up of the
event loop costs more CPU than the request it sends (epoll, timers, cold caches): 50 modules
spread over 50 phases cost 2.5x the CPU of the same modules woken together (bench modbus),
while 4 phases keep each group small enough that its last request leaves well within 1 ms."""


class HealthState(StrEnum):
    connecting = "connecting"
    online = "online"  # answering normally
    faulty = "faulty"  # answering, but with Modbus exception codes
    offline = "offline"  # no connection or no answer in time


@dataclass
class ModuleHealth:
    module: str
    state: HealthState = HealthState.connecting
    rtt_ms: float | None = None
    errors: int = 0
    last_error: str | None = None
    polls: int = 0
    overruns: int = 0

    @property
    def online(self) -> bool:
        return self.state in (HealthState.online, HealthState.faulty)

    def payload(self) -> BuildingModuleHealth:
        """building_module_health payload (docs/messages.md)."""
        return BuildingModuleHealth(
            module=self.module,
            online=self.state == HealthState.online,
            rtt_ms=None if self.rtt_ms is None else round(self.rtt_ms, 3),
            errors=self.errors,
            last_error=self.last_error,
        )


@dataclass
class ModulePoller:
    """Polls one module; calls ``on_sample(module_id, sample, t)`` and ``on_health(health)``.

    ``t`` is the poll's slot on the schedule, not its actual start: the input filter then
    compares whole periods, and a late wake-up cannot make a held press look 1 ms too short.
    A poll more than 10 ms late is stamped with its real start instead.
    """

    module: BuildingModule
    on_sample: Callable[[str, Sample, float], None]
    on_health: Callable[[ModuleHealth], None]
    health_interval_s: float = 5.0
    phase: float = 0.0
    """Fraction of a period to wait before the first poll: spreads modules over the period so
    they do not all wake at the same instant (which would make the last one late)."""
    jitter_s: collections.deque[float] = field(
        default_factory=lambda: collections.deque(maxlen=JITTER_SAMPLES)
    )
    interval_s: collections.deque[float] = field(
        default_factory=lambda: collections.deque(maxlen=JITTER_SAMPLES)
    )
    """Time between the starts of consecutive polls (none across a reconnect)."""

    def __post_init__(self) -> None:
        self.client = ModuleClient(
            self.module.host,
            self.module.port,
            unit_id=self.module.unit_id,
            timeout_s=self.module.timeout_ms / 1000,
        )
        self.health = ModuleHealth(self.module.id)
        self.period_s = self.module.sampling_period_ms / 1000
        self.ranges: dict[PointKind, tuple[int, int]] = {}
        for kind in PointKind:
            addresses = [p.address for p in self.module.points if p.kind == kind]
            if addresses:
                self.ranges[kind] = (min(addresses), max(addresses) - min(addresses) + 1)
        self._task: asyncio.Task[None] | None = None
        self._last_health_report = -math.inf

    @property
    def running(self) -> bool:
        return self._task is not None and not self._task.done()

    def start(self) -> None:
        self._task = asyncio.create_task(self._run(), name=f"building-poll-{self.module.id}")

    async def stop(self) -> None:
        task, self._task = self._task, None
        await cancel_and_wait(task)  # cancelled until really done (pymodbus's wait_for)
        self.client.close()

    def _set_health(self, state: HealthState, error: str | None = None) -> None:
        """Report on every change of state, and at least every health_interval_s."""
        changed = state != self.health.state or (
            error is not None and error != self.health.last_error
        )
        self.health.state = state
        if error is not None:
            self.health.errors += 1
            self.health.last_error = error
        now = asyncio.get_running_loop().time()
        if changed or now - self._last_health_report >= self.health_interval_s:
            self._last_health_report = now
            self.on_health(self.health)

    async def _run(self) -> None:
        # time.monotonic, not loop.time: uvloop's loop clock has 1 ms steps.
        clock = time.monotonic
        backoff = BACKOFF_FIRST_S
        await asyncio.sleep(math.floor(self.phase * PHASE_GROUPS) / PHASE_GROUPS * self.period_s)
        due = clock()
        me = asyncio.current_task()
        last_woke: float | None = None
        while me is None or not me.cancelling():
            if not self.client.connected:
                last_woke = None
                try:
                    await self.client.connect()
                except ModuleUnreachable as exc:
                    self._set_health(HealthState.offline, str(exc))
                    await asyncio.sleep(backoff)
                    backoff = min(backoff * 2, BACKOFF_MAX_S)
                    continue
                backoff = BACKOFF_FIRST_S
                # Back on the grid after a (re)connect, keeping this module's phase.
                now = clock()
                due += math.ceil(max(0.0, now - due) / self.period_s) * self.period_s
                await asyncio.sleep(due - now)
            woke = clock()
            self.jitter_s.append(abs(woke - due))  # timers may also fire a little early
            if last_woke is not None:
                self.interval_s.append(woke - last_woke)
            last_woke = woke
            try:
                sample: Sample = {}
                for kind, (first, count) in self.ranges.items():
                    sample[kind] = (first, await self.client.read(kind, first, count))
                self.health.rtt_ms = (clock() - woke) * 1000
                self.health.polls += 1
                # The slot, unless this poll ran late: then the real time, so that a stalled
                # loop cannot stretch a short pulse into one that passes the filter.
                stamp = due if woke - due <= SLOT_STAMP_MAX_LATE_S else woke
                self.on_sample(self.module.id, sample, stamp)
                self._set_health(HealthState.online)
            except ModuleExceptionAnswer as exc:
                self._set_health(HealthState.faulty, str(exc))
            except ModuleUnreachable as exc:
                self._set_health(HealthState.offline, str(exc))
                continue  # reconnect (with back-off) at the top of the loop
            except ModbusIOError as exc:  # pragma: no cover - a programming error in ranges
                log.error("module %s: %s", self.module.id, exc)
            due += self.period_s
            now = clock()
            if due < now:  # a slow answer overran one or more slots: skip them
                missed = math.ceil((now - due) / self.period_s)
                self.health.overruns += missed
                due += missed * self.period_s
            await asyncio.sleep(due - now)
