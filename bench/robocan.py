"""``guidebot bench robocan``: hot-plug detection, unplug detection, master throughput and
command latency, on python-can's virtual bus with the simulated BellBot.

- plug_detect_ms: a module powered on -> the master publishes module_status "online" for it
  (discovery, query, description block, configuration and enable: the whole bring-up).
- unplug_detect_ms: a module powered off -> module_status "lost" (bound: its last watchdog
  plus 3.5 watchdog periods, 250..350 ms with the 100 ms default).
- frames_per_s_at_50pct_cpu: valid encoder frames the master (its reader thread and the
  event loop thread) handles per second when using half of one core, from the CPU time it
  spent on a paced flood sent by another thread.
- command_to_frame_ms: set_velocity published on the on-board bus -> the velocity frame's
  timestamp on the CAN bus.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from typing import Any

import can
import click
import psutil

from guidebot.benchutil import percentiles, print_result
from guidebot.bus import Bus
from robot_agent.robocan import protocol as p
from robot_agent.robocan.busopen import open_bus
from robot_agent.robocan.stack import RoboCanStack


async def _wait(condition: Any, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError("condition not met in time")
        await asyncio.sleep(0.001)


async def plug_cycles(cycles: int) -> tuple[list[float], list[float]]:
    bus = Bus()
    endpoint, watcher = bus.endpoint("robocan"), bus.endpoint("watcher")
    status: dict[int, tuple[str, float]] = {}
    watcher.subscribe(
        "module_status",
        lambda m: status.__setitem__(
            m.payload["module_id"], (m.payload["state"], time.perf_counter())
        ),
    )
    channel = f"virtual:bench-plug-{time.monotonic_ns()}"
    plug_ms, unplug_ms = [], []
    async with RoboCanStack(endpoint, [channel], layout={0x02: "motor", 0x40: "head"}) as stack:
        await stack.wait_online()
        for _ in range(cycles):
            await stack.unplug(0x40)
            t0 = time.perf_counter()
            await _wait(lambda: status.get(0x40, ("",))[0] == "lost")
            unplug_ms.append((status[0x40][1] - t0) * 1000)
            t0 = time.perf_counter()
            await stack.plug(0x40)
            await _wait(lambda: status.get(0x40, ("",))[0] == "online")
            plug_ms.append((status[0x40][1] - t0) * 1000)
    return plug_ms, unplug_ms


def _thread_cpu(native_ids: set[int]) -> float:
    return sum(
        t.user_time + t.system_time for t in psutil.Process().threads() if t.id in native_ids
    )


async def throughput(frames: int) -> float:
    bus = Bus()
    endpoint = bus.endpoint("robocan")
    bus.endpoint("navigation").subscribe("odometry", lambda m: None)
    channel = f"virtual:bench-flood-{time.monotonic_ns()}"
    async with RoboCanStack(endpoint, [channel], layout={0x02: "motor"}) as stack:
        await stack.wait_online()
        master = stack.masters[0]
        assert master.reader is not None
        ids = {threading.main_thread().native_id or 0, master.reader.native_id or 0}
        flood = open_bus(channel)
        done = threading.Event()

        def sender() -> None:
            for i in range(frames):
                flood.send(
                    can.Message(
                        arbitration_id=0x02, data=p.encoder(0, i, 0.0), is_extended_id=False
                    )
                )
                if i % 64 == 63:
                    time.sleep(0.002)  # paced: the benchmark measures work, not overflow
            done.set()

        start_rx = master.counters.frames_rx + master.counters.overflow
        cpu0 = _thread_cpu(ids)
        thread = threading.Thread(target=sender, name="bench-flood", daemon=True)
        thread.start()
        await _wait(
            lambda: master.counters.frames_rx + master.counters.overflow - start_rx >= frames,
            timeout=120,
        )
        cpu = _thread_cpu(ids) - cpu0
        thread.join()
        flood.shutdown()
        handled = master.counters.frames_rx - start_rx
    if cpu < 0.05:
        raise click.UsageError(f"{frames} frames cost too little CPU to measure: use more")
    return 0.5 * handled / cpu


async def command_latency(samples: int) -> list[float]:
    bus = Bus()
    endpoint, navigation = bus.endpoint("robocan"), bus.endpoint("navigation")
    channel = f"virtual:bench-cmd-{time.monotonic_ns()}"
    seen: dict[int, float] = {}

    def on_frame(msg: can.Message) -> None:
        if msg.arbitration_id == 0x03 and msg.data[0] == p.Op.SET_VELOCITY:
            _, velocity, _ = p.parse_set_velocity(bytes(msg.data))
            seen.setdefault(round(velocity * 1e6), msg.timestamp)

    tap = open_bus(channel)
    notifier = can.Notifier(tap, [on_frame], timeout=0.05)
    latencies = []
    try:
        async with RoboCanStack(endpoint, [channel], layout={0x02: "motor", 0x04: "motor"}) as st:
            await st.wait_online()
            for i in range(samples):
                v = 0.1 + 0.001 * i
                t0 = time.time()
                navigation.publish("set_velocity", {"v": v, "w": 0.0})
                key = round(v * 1e6)
                await _wait(lambda key=key: key in seen)
                latencies.append((seen[key] - t0) * 1000)
                await asyncio.sleep(0.01)
            navigation.publish("set_velocity", {"v": 0.0, "w": 0.0})
    finally:
        await asyncio.to_thread(notifier.stop, 1.0)
        tap.shutdown()
    return latencies


@click.command()
@click.option("--cycles", type=click.IntRange(min=1), default=20, show_default=True)
@click.option("--frames", type=click.IntRange(min=100), default=50000, show_default=True)
@click.option("--samples", type=click.IntRange(min=1), default=200, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Only the closing JSON line.")
def main(cycles: int, frames: int, samples: int, as_json: bool) -> None:
    """Plug/unplug detection, master throughput and command-to-frame latency."""

    async def run() -> dict[str, Any]:
        plug, unplug = await plug_cycles(cycles)
        rate = await throughput(frames)
        latency = await command_latency(samples)
        return {
            "plug_detect_ms": percentiles(plug),
            "unplug_detect_ms": percentiles(unplug),
            "frames_per_s_at_50pct_cpu": round(rate),
            "command_to_frame_ms": percentiles(latency),
        }

    logger = logging.getLogger("robot_agent.robocan")
    level = logger.level
    logger.setLevel(logging.ERROR)  # lost modules are expected here
    try:
        result = asyncio.run(run())
    finally:
        logger.setLevel(level)
    if not as_json:
        click.echo(
            f"plug -> online {result['plug_detect_ms']} ms, unplug -> lost "
            f"{result['unplug_detect_ms']} ms, {result['frames_per_s_at_50pct_cpu']} frames/s "
            f"at 50% of a core, set_velocity -> frame {result['command_to_frame_ms']} ms"
        )
    print_result(result)
