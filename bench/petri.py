"""``guidebot bench petri``: RoboGraph start latency, firing rate and memory per instance.

start = from publishing run_petri_net on the bus to the first action message of the net (a
give_tour: its first message is navigate_to, published by its navigate_to_point sub-net), with
monitoring events on. The paper measured 329 ms here, partly loading XML; we parse once.
"""

from __future__ import annotations

import asyncio
import gc
import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import click
import psutil

from guidebot.benchutil import percentiles, print_result
from guidebot.bus import Bus
from guidebot.messages import Message
from petri_nets.builder import NetBuilder
from petri_nets.clock import AsyncioClock
from petri_nets.dispatch import Dispatch
from petri_nets.library import DEFAULT_LIBRARY, NetLibrary
from petri_nets.pnml import write_pnml

TOUR = {
    "tour": "t1",
    "points": [
        {"node": f"n{i}", "poi": f"p{i}", "text": f"Point {i} of the tour."} for i in range(3)
    ],
}


def chain_net(length: int) -> bytes:
    """A chain of unconditioned transitions: p0 -> t0 -> p1 -> ... -> p{length} (final)."""
    b = NetBuilder("chain", "benchmark chain")
    for i in range(length + 1):
        b.place(f"p{i}", initial=1 if i == 0 else 0, final=i == length)
    for i in range(length):
        b.transition(f"t{i}", [f"p{i}"], [f"p{i + 1}"])
    return write_pnml(b.build())


def measure_start(dispatch: Dispatch, bus: Bus, samples: int) -> list[float]:
    client = bus.endpoint("bench-client")
    arrived: list[float] = []
    client.subscribe("navigate_to", lambda m: arrived.append(time.perf_counter()))
    times = []
    for i in range(samples):
        arrived.clear()
        params = json.loads(json.dumps(TOUR))
        message = Message(
            type="run_petri_net",
            source="bench-client",
            payload={"net": "give_tour", "instance_id": f"s{i}", "params": params},
        )
        t0 = time.perf_counter()
        bus.publish(message)
        if not arrived:
            raise RuntimeError("give_tour published no navigate_to")
        times.append((arrived[0] - t0) * 1000)
        dispatch.kill(f"s{i}")
    client.close()
    return times


def measure_firings(dispatch: Dispatch, length: int, rounds: int) -> float:
    rates = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        dispatch.start("chain", {})
        rates.append(length / (time.perf_counter() - t0))
    return statistics.median(rates)


def measure_memory(dispatch: Dispatch, count: int) -> float:
    """RSS growth (MB) per 1000 tours, with ``count`` tours (and their sub-nets) at once."""
    params = [json.loads(json.dumps(TOUR)) for _ in range(count)]  # as if from messages
    gc.collect()
    process = psutil.Process()
    before = process.memory_info().rss
    ids = [dispatch.start("give_tour", p) for p in params]
    gc.collect()
    after = process.memory_info().rss
    if len(dispatch.running()) < 2 * count:  # each tour also runs navigate_to_point
        raise RuntimeError("give_tour instances did not stay running")
    for instance_id in ids:
        dispatch.kill(instance_id)
    return (after - before) / 1e6 * 1000 / count


async def run_bench(folder: Path, samples: int, length: int, instances: int) -> dict[str, Any]:
    bus = Bus()
    dispatch = Dispatch(bus.endpoint("dispatch"), NetLibrary(folder), AsyncioClock(), idle_net=None)
    dispatch.open()
    try:
        # RSS first, and over 10x the instances: memory freed by loading would hide growth
        rss = measure_memory(dispatch, 10 * instances)
        gc.collect()  # the killed tours are garbage: collect them now, not during the timing
        measure_start(dispatch, bus, 50)  # warm-up
        start = measure_start(dispatch, bus, samples)
        firings = measure_firings(dispatch, length, 7)
    finally:
        dispatch.close()
    return {
        "start_ms": percentiles(start, digits=4),
        "firings_per_s": round(firings),
        "instances": instances,
        "rss_mb_per_1000_instances": round(rss, 2),
    }


@click.command()
@click.option("--samples", default=2000, show_default=True, help="Starts to time.")
@click.option(
    "--chain",
    "length",
    default=5000,
    show_default=True,
    help="Transitions in the firing-rate chain.",
)
@click.option(
    "--instances",
    default=1000,
    show_default=True,
    help="Concurrent give_tour instances for the memory figure.",
)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line.")
def main(samples: int, length: int, instances: int, as_json: bool) -> None:
    """Start latency (p50/p99 ms), firings per second, RSS per 1000 give_tour instances."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for path in DEFAULT_LIBRARY.glob("*.pnml"):
            (folder / path.name).write_bytes(path.read_bytes())
        (folder / "chain.pnml").write_bytes(chain_net(length))
        result = asyncio.run(run_bench(folder, samples, length, instances))
    if not as_json:
        click.echo("goals: start p50 < 0.5 ms, >= 50000 firings/s, < 50 MB per 1000 tours")
    print_result(result)
