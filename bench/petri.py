"""``guidebot bench petri``: RoboGraph start latency, firing rate, monitoring cost, compile time,
memory per instance, and (``--peer``) SNAKES side by side.

start = from publishing run_petri_net on the bus to the first action message of the net (a
give_tour: its first message is navigate_to, published by its navigate_to_point sub-net), with
monitoring events on. The paper measured 329 ms here, partly loading XML; we parse once.

Every firing figure is taken with monitoring on and a monitor subscribed to petri_net_event
(counting the firings it is told of, which is also how answers are checked), unless it says
"unmonitored". Figures are medians of ``--rounds`` runs; contenders (monitored/unmonitored,
ours/the peer) alternate within each round so load on the machine hits them alike, and ratios
between contenders are taken on CPU seconds (rates are wall clock).
"""

from __future__ import annotations

import asyncio
import gc
import heapq
import json
import statistics
import tempfile
import time
import warnings
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

import click
import psutil

from guidebot.benchutil import percentiles, print_result
from guidebot.bus import Bus
from guidebot.messages import Message
from petri_nets.builder import NetBuilder
from petri_nets.clock import AsyncioClock
from petri_nets.compiled import compile_net
from petri_nets.dispatch import Dispatch
from petri_nets.library import DEFAULT_LIBRARY, NetLibrary
from petri_nets.model import NetDoc
from petri_nets.pnml import read_pnml, write_pnml
from petri_nets.validate import validate

TOUR = {
    "tour": "t1",
    "points": [
        {"node": f"n{i}", "poi": f"p{i}", "text": f"Point {i} of the tour."} for i in range(3)
    ],
}
RING_PLACES = 100


def chain_net(length: int, name: str = "chain") -> NetDoc:
    """A chain of unconditioned transitions: p0 -> t0 -> p1 -> ... -> p{length} (final)."""
    b = NetBuilder(name, "benchmark chain")
    for i in range(length + 1):
        b.place(f"p{i}", initial=1 if i == 0 else 0, final=i == length)
    for i in range(length):
        b.transition(f"t{i}", [f"p{i}"], [f"p{i + 1}"])
    return b.build()


def ring_net(places: int, laps: int, name: str = "ring") -> NetDoc:
    """A mark going round ``places`` places ``laps`` times (t0 also takes one ``fuel`` mark),
    then resting in r0 (final): places x laps firings, over several engine steps."""
    b = NetBuilder(name, "benchmark ring")
    for i in range(places):
        b.place(f"r{i}", initial=1 if i == 0 else 0, final=i == 0)
    b.place("fuel", initial=laps)
    for i in range(places):
        inputs = [f"r{i}", "fuel"] if i == 0 else [f"r{i}"]
        b.transition(f"t{i}", inputs, [f"r{(i + 1) % places}"])
    return b.build()


class Timing:
    """Wall-clock and CPU seconds of one run. Rates are wall clock; ratios between contenders
    are taken on CPU seconds, which other processes on a shared machine do not inflate."""

    def __init__(self) -> None:
        self.wall = time.perf_counter()
        self.cpu = time.process_time()

    def stop(self) -> Timing:
        self.wall = time.perf_counter() - self.wall
        self.cpu = max(time.process_time() - self.cpu, 1e-9)
        return self


class Runner:
    """Our engine as a user runs it: a dispatch on the asyncio loop, a monitor listening."""

    def __init__(self, folder: Path) -> None:
        self.bus = Bus()
        self.dispatch = Dispatch(
            self.bus.endpoint("dispatch"), NetLibrary(folder), AsyncioClock(), idle_net=None
        )
        self.firings: dict[str, int] = {}
        self.marking: dict[str, dict[str, int]] = {}
        self.ended: dict[str, asyncio.Future[str]] = {}
        monitor = self.bus.endpoint("monitor")
        monitor.subscribe("petri_net_event", self._on_event)
        monitor.subscribe("petri_net_ended", self._on_ended)

    def _on_event(self, message: Message) -> None:
        payload = message.payload
        iid = payload["instance_id"]
        if payload["kind"] == "fired":
            self.firings[iid] = self.firings.get(iid, 0) + len(payload["transitions"])
        elif payload["kind"] == "ended":
            self.marking[iid] = {k: v for k, v in payload["marking"].items() if v}

    def _on_ended(self, message: Message) -> None:
        future = self.ended.get(message.payload["instance_id"])
        if future is not None and not future.done():
            future.set_result(message.payload["outcome"])

    async def run(self, net: str, *, monitor: bool = True) -> tuple[Timing, int, dict[str, int]]:
        """Time from start to end, firings and final marking (those two monitored only)."""
        self.dispatch.monitor = monitor
        iid = f"{net}#{len(self.ended)}"
        self.ended[iid] = asyncio.get_running_loop().create_future()
        timing = Timing()
        self.dispatch.start(net, instance_id=iid)
        outcome = await self.ended[iid]
        timing.stop()
        self.dispatch.monitor = True
        if outcome != "done":
            raise RuntimeError(f"{net} ended {outcome}")
        return timing, self.firings.pop(iid, 0), self.marking.pop(iid, {})


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


def measure_memory(dispatch: Dispatch, count: int) -> float:
    """RSS growth (MB) per 1000 tours, with ``count`` tours (and their sub-nets) at once."""
    params = [json.loads(json.dumps(TOUR)) for _ in range(count)]  # as if from messages
    gc.collect()
    process = psutil.Process()
    before = process.memory_info().rss
    ids = [dispatch.start("give_tour", p) for p in params]
    gc.collect()
    after = process.memory_info().rss
    if len(dispatch.running()) < count:  # give_tour publishes navigate_to itself (no sub-net)
        raise RuntimeError("give_tour instances did not stay running")
    for instance_id in ids:
        dispatch.kill(instance_id)
    return (after - before) / 1e6 * 1000 / count


def median_ms(action: Callable[[], object], repeat: int) -> float:
    """Median CPU milliseconds of ``action`` (CPU: a loaded machine does not inflate it)."""
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        action()
        times.append(time.process_time() - t0)
    return statistics.median(times) * 1000


def measure_compile(ring: bytes, repeat: int) -> dict[str, float]:
    """compile_ms: validated model -> tables; load_ms: PNML bytes -> read, validate, compile."""
    doc, _ = read_pnml(ring, "ring.pnml")
    assert doc is not None

    def load() -> None:
        loaded, problems = read_pnml(ring, "ring.pnml")
        assert loaded is not None and not problems and not validate(loaded)
        compile_net(loaded)

    return {
        "compile_ms": round(median_ms(lambda: compile_net(doc), repeat), 3),
        "load_ms": round(median_ms(load, repeat), 3),
    }


async def measure_ring(runner: Runner, firings: int, rounds: int) -> dict[str, Any]:
    """Monitored and unmonitored firing rates on the ring, alternating within each round."""
    rates: dict[bool, list[float]] = {True: [], False: []}
    cpu: dict[bool, list[float]] = {True: [], False: []}
    for r in range(rounds):
        for monitor in (r % 2 == 0, r % 2 == 1):
            timing, counted, _ = await runner.run("ring", monitor=monitor)
            if monitor and counted != firings:
                raise RuntimeError(f"the monitor was told of {counted} firings, not {firings}")
            rates[monitor].append(firings / timing.wall)
            cpu[monitor].append(timing.cpu)
    on, off = statistics.median(rates[True]), statistics.median(rates[False])
    return {
        "ring_firings_per_s": {"monitored": round(on), "unmonitored": round(off)},
        "monitor_cost": round(statistics.median(cpu[True]) / statistics.median(cpu[False]), 2),
    }


# ---------------------------------------------------------------- the peer: SNAKES


class SnakesNet:
    """The same net in SNAKES, run with the same algorithm and conflict rule as ours (candidate
    transitions in a heap by document order, rechecked when an input place gains marks), so
    the comparison is of the two libraries' marking and firing, not of two schedulers."""

    def __init__(self, doc: NetDoc) -> None:
        try:
            with warnings.catch_warnings():  # SNAKES imports the deprecated imp module
                warnings.simplefilter("ignore", DeprecationWarning)
                from snakes.nets import (
                    MultiArc,
                    PetriNet,
                    Place,
                    Substitution,
                    Transition,
                    Value,
                    dot,
                )
        except ImportError:
            raise click.ClickException("--peer needs SNAKES: pip install -e '.[peers]'") from None
        net = PetriNet(doc.id)
        places = {p.id for p in doc.places}
        for place in doc.places:
            net.add_place(Place(place.id, [dot] * place.initial))
        for trans in doc.transitions:
            net.add_transition(Transition(trans.id))
        downstream: dict[str, list[int]] = {p: [] for p in places}
        outputs: list[list[str]] = [[] for _ in doc.transitions]
        index = {t.id: i for i, t in enumerate(doc.transitions)}
        for arc in doc.arcs:
            label = Value(dot) if arc.weight == 1 else MultiArc([Value(dot)] * arc.weight)
            if arc.source in places:
                net.add_input(arc.source, arc.target, label)
                downstream[arc.source].append(index[arc.target])
            else:
                net.add_output(arc.target, arc.source, label)
                outputs[index[arc.source]].append(arc.target)
        self.net = net
        self.transitions = [net.transition(t.id) for t in doc.transitions]
        self.after = [sorted({d for p in outs for d in downstream[p]}) for outs in outputs]
        self.start = sorted({d for p in doc.places if p.initial for d in downstream[p.id]})
        self.binding = Substitution()

    def run(self) -> tuple[int, dict[str, int]]:
        """Fire until nothing is enabled: firings and final marking."""
        heap = list(self.start)
        transitions, after, binding = self.transitions, self.after, self.binding
        fired = 0
        while heap:
            t = heapq.heappop(heap)
            while heap and heap[0] == t:
                heapq.heappop(heap)
            if transitions[t].enabled(binding):
                transitions[t].fire(binding)
                fired += 1
                heapq.heappush(heap, t)
                for d in after[t]:
                    heapq.heappush(heap, d)
        marking = {p.name: len(p.tokens) for p in self.net.place() if len(p.tokens)}
        return fired, marking


async def measure_peer(
    runner: Runner, nets: dict[str, NetDoc], rounds: int
) -> tuple[dict[str, Any], dict[str, float]]:
    """Ours and SNAKES on the same nets, interleaved, answers (firings, marking) checked."""
    ours: dict[str, list[float]] = {name: [] for name in nets}
    theirs: dict[str, list[float]] = {name: [] for name in nets}
    ours_cpu: dict[str, list[float]] = {name: [] for name in nets}
    theirs_cpu: dict[str, list[float]] = {name: [] for name in nets}
    for r in range(rounds):
        for name, doc in nets.items():
            snakes = SnakesNet(doc)  # a fresh net each run: SNAKES fires in place
            for contender in ("ours", "peer") if r % 2 == 0 else ("peer", "ours"):
                if contender == "ours":
                    timing, fired, marking = await runner.run(name)
                    ours[name].append(fired / timing.wall)
                    ours_cpu[name].append(timing.cpu)
                    answer = (fired, marking)
                else:
                    timing = Timing()
                    fired, marking = snakes.run()
                    theirs[name].append(fired / timing.stop().wall)
                    theirs_cpu[name].append(timing.cpu)
                    peer_answer = (fired, marking)
            if answer != peer_answer:
                raise RuntimeError(f"{name}: ours {answer} but SNAKES {peer_answer}")
    keys = {"peer_chain": "firings_per_s", "peer_ring": "ring_firings_per_s"}
    peer = {
        "library": f"SNAKES {metadata.version('snakes')}",
        "answers_equal": True,
        **{keys[name]: round(statistics.median(theirs[name])) for name in nets},
    }
    ratio = {  # ours / SNAKES in speed: their CPU seconds over ours, same firings
        keys[name]: round(
            statistics.median(theirs_cpu[name]) / statistics.median(ours_cpu[name]), 1
        )
        for name in nets
    }
    return peer, ratio


async def run_bench(
    folder: Path,
    samples: int,
    length: int,
    instances: int,
    laps: int,
    rounds: int,
    peer_nets: dict[str, NetDoc] | None,
) -> dict[str, Any]:
    runner = Runner(folder)
    dispatch = runner.dispatch
    dispatch.open()
    try:
        # RSS first, and over 10x the instances: memory freed by loading would hide growth
        rss = measure_memory(dispatch, 10 * instances)
        gc.collect()  # the killed tours are garbage: collect them now, not during the timing
        measure_start(dispatch, runner.bus, 50)  # warm-up
        start = measure_start(dispatch, runner.bus, samples)
        chain = [length / (await runner.run("chain"))[0].wall for _ in range(rounds)]
        ring = await measure_ring(runner, RING_PLACES * laps, rounds)
        peer = await measure_peer(runner, peer_nets, rounds) if peer_nets else None
    finally:
        dispatch.close()
    result: dict[str, Any] = {
        "start_ms": percentiles(start, digits=4),
        "firings_per_s": round(statistics.median(chain)),
        **ring,
        "instances": instances,
        "rss_mb_per_1000_instances": round(rss, 2),
        "rounds": rounds,
    }
    if peer is not None:
        result["peer"], result["ratio"] = peer
    return result


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
    "--laps",
    default=2000,
    show_default=True,
    help="Laps of the mark round the 100-place ring (100 firings each).",
)
@click.option(
    "--instances",
    default=1000,
    show_default=True,
    help="Concurrent give_tour instances for the memory figure.",
)
@click.option("--rounds", default=7, show_default=True, help="Runs per figure (median).")
@click.option(
    "--peer", is_flag=True, help="Run SNAKES on the same nets, interleaved (extra 'peers')."
)
@click.option(
    "--peer-size",
    default=2000,
    show_default=True,
    help="Firings of each net in the SNAKES comparison (a chain, and a 100-place ring).",
)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line.")
def main(
    samples: int,
    length: int,
    laps: int,
    instances: int,
    rounds: int,
    peer: bool,
    peer_size: int,
    as_json: bool,
) -> None:
    """Start latency, firing rates and monitoring cost, compile time, RSS per 1000 tours."""
    ring = write_pnml(ring_net(RING_PLACES, 1))
    compiled = measure_compile(ring, repeat=max(20, 5 * rounds))
    peer_nets = None
    if peer:
        peer_nets = {
            "peer_chain": chain_net(peer_size, "peer_chain"),
            "peer_ring": ring_net(RING_PLACES, max(1, peer_size // RING_PLACES), "peer_ring"),
        }
        SnakesNet(peer_nets["peer_chain"])  # fail early when SNAKES is missing
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for path in DEFAULT_LIBRARY.glob("*.pnml"):
            (folder / path.name).write_bytes(path.read_bytes())
        (folder / "chain.pnml").write_bytes(write_pnml(chain_net(length)))
        (folder / "ring.pnml").write_bytes(write_pnml(ring_net(RING_PLACES, laps)))
        for name, doc in (peer_nets or {}).items():
            (folder / f"{name}.pnml").write_bytes(write_pnml(doc))
        result = asyncio.run(run_bench(folder, samples, length, instances, laps, rounds, peer_nets))
    result.update(compiled)
    if not as_json:
        click.echo(
            "goals: start p50 < 0.5 ms, >= 50000 firings/s, monitor_cost <= 1.5, "
            "compile_ms < 1 (100 places), < 50 MB per 1000 tours"
        )
    print_result(result)
