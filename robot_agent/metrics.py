"""A robot agent's Prometheus metrics, served on its touch-screen port (``GET /metrics``).

CAN frames and errors come from the RoboCAN master's own counters, read at scrape time; module
losses are counted from ``module_status`` on the on-board bus; the loop lag is measured by a
task that sleeps 0.5 s and records how late it wakes (docs/metrics.md).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterable
from typing import Any

from prometheus_client import CollectorRegistry, Histogram, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.service import Service

__all__ = ["RobotMetrics"]

LAG_PERIOD_S = 0.5
BITRATE = 1_000_000
FRAME_BITS_MAX = 135  # 8 data bytes, worst-case stuffing, interframe space (docs/robocan.md)
COUNTERS = ("frames_rx", "frames_tx", "bad_frame", "unknown_id", "send_errors", "overflow")


class RobotMetrics(Service):
    """Registry of one agent; ``masters()`` lists its RoboCAN masters (none without CAN)."""

    def __init__(self, endpoint: Endpoint, robot: str, masters: Callable[[], list[Any]]) -> None:
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.masters = masters
        self.registry = CollectorRegistry(auto_describe=False)
        self.loop_lag = Histogram(
            "guidebot_robot_loop_lag_seconds",
            "How late the event loop wakes a 0.5 s sleep",
            buckets=(0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0),
            registry=self.registry,
        )
        self.losses = 0
        self._last: tuple[float, int] | None = None
        self.registry.register(_CanCollector(self))

    async def on_start(self) -> None:
        self.subscribe(self.ep, "module_status", self._on_status)
        self.spawn(self._watch_lag(), name="loop-lag")

    def _on_status(self, message: Message) -> None:
        if message.payload.get("state") == "lost":
            self.losses += 1

    async def _watch_lag(self) -> None:
        while True:
            asked = time.monotonic() + LAG_PERIOD_S
            await asyncio.sleep(LAG_PERIOD_S)
            self.loop_lag.observe(max(0.0, time.monotonic() - asked))

    def bus_load(self, frames: int) -> float:
        """Upper bound of the bus load since the previous scrape (every frame counted as a
        full 8-byte frame with worst-case stuffing)."""
        now = time.monotonic()
        last, self._last = self._last, (now, frames)
        if last is None or now <= last[0]:
            return 0.0
        return (frames - last[1]) * FRAME_BITS_MAX / (now - last[0]) / BITRATE

    def render(self) -> bytes:
        return generate_latest(self.registry)


class _CanCollector(Collector):
    def __init__(self, metrics: RobotMetrics) -> None:
        self.m = metrics

    def collect(self) -> Iterable[Metric]:
        m = self.m
        masters = m.masters()
        frames = CounterMetricFamily(
            "guidebot_can_frames",
            "CAN frames and errors the RoboCAN master counted",
            labels=["kind"],
        )
        totals = {name: sum(getattr(x.counters, name) for x in masters) for name in COUNTERS}
        for name, value in totals.items():
            frames.add_metric([name], value)
        yield frames
        yield GaugeMetricFamily(
            "guidebot_can_bus_load_ratio",
            "CAN bus load since the previous scrape, upper bound (1 Mbit/s)",
            value=m.bus_load(totals["frames_rx"] + totals["frames_tx"]),
        )
        modules = GaugeMetricFamily("guidebot_can_modules", "Modules by state", labels=["state"])
        states: dict[str, int] = {}
        for master in masters:
            for module in master.modules.values():
                states[module.state.value] = states.get(module.state.value, 0) + 1
        for state, count in sorted(states.items()):
            modules.add_metric([state], count)
        yield modules
        yield CounterMetricFamily(
            "guidebot_can_module_losses", "Modules lost (watchdog time-out)", value=m.losses
        )
