"""BuildingInterface benchmark: polling jitter, CPU and press-to-event latency over real Modbus/TCP.

    guidebot bench modbus --modules 50 --json

The building simulator runs in its own process (``python -m building_sim``) with N modules of
8 buttons each on loopback; this process runs the BuildingInterface on an in-process hub, as the
server does. Last line:
{"modules", "period_ms", "jitter_ms": {"p50", "p99"}, "cpu_percent", "detect_ms": {"p50", "p99"}}

- jitter_ms: how late each poll started against its fixed schedule (start + n x period).
- cpu_percent: CPU time of this process (the BuildingInterface alone, not the simulator) over
  the measured window, in percent of one core.
- detect_ms: from the control API call that starts a press (sent: the press cannot start
  before it, so the figure never understates) to its building_input_changed on the hub.
  Floor: filter + half a period on average (200 + 100 ms).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import json
import random
import statistics
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import click
import httpx
import psutil
import yaml

from backend.building.interface import BuildingInterface
from guidebot.benchutil import percentiles, print_result
from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.site.building import PointKind
from guidebot.site.building_config import BuildingConfig, load_building

__all__ = ["main"]

BUTTONS_PER_MODULE = 8
PRESSERS = 5  # concurrent "visitors", each on its own modules


def synthetic_building(modules: int, period_ms: int) -> dict[str, Any]:
    """N OTB-like modules: 8 button inputs and 8 LED coils each, a button per input."""
    mods, buttons = [], []
    for m in range(modules):
        points = [
            {"name": f"in{i}", "address": i, "kind": "discrete_input", "node": f"n{m}_{i}"}
            for i in range(BUTTONS_PER_MODULE)
        ] + [{"name": f"led{i}", "address": i, "kind": "coil"} for i in range(BUTTONS_PER_MODULE)]
        mods.append(
            {
                "id": f"m{m}",
                "port": 0,
                "sampling_period_ms": period_ms,
                "timeout_ms": max(period_ms * 2, 100),
                "points": points,
            }
        )
        buttons += [
            {
                "id": f"b{m}_{i}",
                "input": {"module": f"m{m}", "point": f"in{i}"},
                "node": f"n{m}_{i}",
                "task": {"kind": "tour"},
            }
            for i in range(BUTTONS_PER_MODULE)
        ]
    return {"modules": mods, "buttons": buttons}


@contextlib.asynccontextmanager
async def simulator_process(site: dict[str, Any]) -> AsyncIterator[dict[str, Any]]:
    """Run building_sim in a child process; yields its ready line (control URL, ports)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "site.yaml"
        path.write_text(yaml.safe_dump(site), encoding="utf-8")
        process = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            "building_sim",
            "--site",
            str(path),
            "--port-zero",
            "--control-port",
            "0",
            stdout=asyncio.subprocess.PIPE,
        )
        try:
            assert process.stdout is not None
            line = await asyncio.wait_for(process.stdout.readline(), 60)
            if not line:
                raise RuntimeError("building simulator exited before it was ready")
            yield json.loads(line)
        finally:
            if process.returncode is None:
                process.terminate()
                await asyncio.wait_for(process.wait(), 20)


class _Timing:
    """Start times of every module's polls, and the last values each read."""

    def __init__(self) -> None:
        self.times: dict[str, list[float]] = {}
        self.last: dict[str, dict[str, list[int]]] = {}

    def record(self, module: str, values: dict[str, list[int]], started: float) -> None:
        self.times.setdefault(module, []).append(started)
        self.last[module] = values

    def intervals(self) -> list[float]:
        return [b - a for t in self.times.values() for a, b in itertools.pairwise(t)]


def _period_figures(
    intervals: list[float], period_s: float, polls: int, window_s: float
) -> dict[str, Any]:
    """period_error_ms = |interval - period| between consecutive poll starts of a module;
    drift_ms_per_poll = how much longer than the period a cycle lasts on average."""
    return {
        "period_error_ms": percentiles([abs(i - period_s) * 1000 for i in intervals]),
        "drift_ms_per_poll": (
            round((statistics.fmean(intervals) - period_s) * 1000, 3) if intervals else None
        ),
        "polls_per_s": round(polls / window_s, 1),
    }


async def _cpu_window(
    seconds: float, timing: _Timing, settle_s: float = 1.0
) -> tuple[float, float]:
    """CPU of this process (percent of one core) over about ``seconds`` after ``settle_s``,
    and the window's real length: a loaded machine wakes the sleep late, and polls counted over
    the longer window but divided by ``seconds`` read 69 polls/s of a 60/s schedule. The poll
    timing is recorded over the same window only."""
    await asyncio.sleep(settle_s)
    timing.times.clear()
    process = psutil.Process()
    cpu0, wall0 = sum(process.cpu_times()[:2]), time.monotonic()
    await asyncio.sleep(seconds)
    cpu, wall = sum(process.cpu_times()[:2]) - cpu0, time.monotonic() - wall0
    for t in timing.times.values():
        # Only polls that started inside the window: one started before it but recorded after
        # the clear (a loaded machine delays the answer) counted too, and the plain peer read
        # 70 polls/s of a 60/s schedule; nor those that started after it closed.
        t[:] = [started for started in t if wall0 <= started <= wall0 + wall]
    return round(cpu / wall * 100, 1), wall


async def _ours_window(
    config: BuildingConfig, filter_ms: float, period_ms: int, seconds: float
) -> dict[str, Any]:
    """The BuildingInterface alone, no presses: CPU, jitter and period error."""
    timing = _Timing()
    async with BuildingInterface(Bus().endpoint("building"), config, filter_ms=filter_ms) as bi:
        for poller in bi.pollers.values():
            inner = poller.on_sample

            def on_sample(module: str, sample: Any, t: float, inner: Any = inner) -> None:
                timing.record(
                    module, {k.value: v for k, (_, v) in sample.items()}, time.monotonic()
                )
                inner(module, sample, t)

            poller.on_sample = on_sample
        await _all_polling(bi)
        await asyncio.sleep(1.0)
        for poller in bi.pollers.values():
            poller.jitter_s.clear()
            poller.interval_s.clear()
        cpu, window_s = await _cpu_window(seconds, timing, settle_s=0.0)
        jitter = [j * 1000 for p in bi.pollers.values() for j in p.jitter_s]
        intervals = [i for p in bi.pollers.values() for i in p.interval_s]
        overruns = sum(p.health.overruns for p in bi.pollers.values())
    polls = sum(len(t) for t in timing.times.values())
    return {
        "cpu_percent": cpu,
        "jitter_ms": percentiles(jitter),
        **_period_figures(intervals, period_ms / 1000, polls, window_s),
        "overruns": overruns,
        "_last": timing.last,
    }


async def _peer_window(config: BuildingConfig, period_ms: int, seconds: float) -> dict[str, Any]:
    """The plain pymodbus loop per module over the same modules: CPU and period error."""
    from .modbus_peer import plain_poll

    timing = _Timing()
    tasks = []
    for module in config.modules:
        kinds = sorted({p.kind for p in module.points}, key=list(PointKind).index)
        ranges = []
        for kind in kinds:
            addresses = [p.address for p in module.points if p.kind == kind]
            ranges.append((kind.value, min(addresses), max(addresses) - min(addresses) + 1))
        record = functools.partial(timing.record, module.id)
        tasks.append(
            asyncio.create_task(
                plain_poll(
                    module.host, module.port, module.unit_id, ranges, period_ms / 1000, record
                )
            )
        )
    try:
        cpu, window_s = await _cpu_window(seconds, timing)
    finally:
        # pymodbus awaits with Python 3.11's wait_for, which can swallow a cancellation that
        # races with an answer: cancel until every loop is really done (as ModulePoller.stop).
        while not all(task.done() for task in tasks):
            for task in tasks:
                task.cancel()
            await asyncio.wait(tasks, timeout=0.5)
    polls = sum(len(t) for t in timing.times.values())
    figures = _period_figures(timing.intervals(), period_ms / 1000, polls, window_s)
    return {"cpu_percent": cpu, **figures, "_last": timing.last}


async def _all_polling(bi: BuildingInterface) -> None:
    deadline = time.monotonic() + 30
    while not all(p.health.polls > 2 for p in bi.pollers.values()):
        if time.monotonic() > deadline:
            raise RuntimeError("modules did not come online within 30 s")
        await asyncio.sleep(0.05)


async def _hold_pattern(http: httpx.AsyncClient, modules: int, seconds: float) -> None:
    """Hold one button per module down (a different one on each) for the CPU windows, so that
    the answers compared between contenders are not all zeros."""
    for m in range(modules):
        reply = await http.post(
            f"/buttons/b{m}_{m % BUTTONS_PER_MODULE}/press", json={"ms": seconds * 1000}
        )
        reply.raise_for_status()


async def _detect(
    config: BuildingConfig,
    modules: int,
    period_ms: int,
    filter_ms: float,
    seconds: float,
    http: httpx.AsyncClient,
) -> tuple[list[float], int]:
    """Press buttons at random: press start -> building_input_changed on the hub."""
    hub = Bus()
    detected: dict[tuple[str, str], asyncio.Future[float]] = {}
    loop = asyncio.get_running_loop()

    def on_change(message: Message) -> None:
        key = (message.payload["module"], message.payload["point"])
        future = detected.get(key)
        if message.payload["value"] and future is not None and not future.done():
            future.set_result(time.monotonic())

    hub.endpoint("bench").subscribe("building_input_changed", on_change)
    async with BuildingInterface(hub.endpoint("building"), config, filter_ms=filter_ms) as bi:
        await _all_polling(bi)
        press_ms = filter_ms + period_ms + 200  # always long enough to be seen
        detect: list[float] = []
        stop_at = time.monotonic() + seconds
        workers = min(PRESSERS, modules)

        async def presser(worker: int) -> None:
            """Presses buttons of its own modules (worker, worker + W, ...), one at a time."""
            rng = random.Random(worker)
            mine = list(range(worker, modules, workers))
            while time.monotonic() < stop_at:
                module = rng.choice(mine)
                button = rng.randrange(BUTTONS_PER_MODULE)
                key = (f"m{module}", f"in{button}")
                future: asyncio.Future[float] = loop.create_future()
                detected[key] = future
                sent = time.monotonic()
                reply = await http.post(f"/buttons/b{module}_{button}/press", json={"ms": press_ms})
                reply.raise_for_status()
                with contextlib.suppress(TimeoutError):
                    detect.append((await asyncio.wait_for(future, 5) - sent) * 1000)
                del detected[key]
                # Let the press end, then a random phase against the poll grid.
                await asyncio.sleep(press_ms / 1000 + rng.uniform(0.05, period_ms / 1000))

        await asyncio.gather(*(presser(w) for w in range(workers)))
        errors = sum(p.health.errors for p in bi.pollers.values())
    return detect, errors


def _median_runs(runs: list[dict[str, Any]]) -> dict[str, Any]:
    def merge(values: list[Any]) -> Any:
        if isinstance(values[0], dict):
            return {k: merge([v[k] for v in values]) for k in values[0]}
        present = [v for v in values if v is not None]
        return round(statistics.median(present), 3) if present else None

    return merge(runs)


async def run(
    modules: int,
    period_ms: int,
    filter_ms: float,
    seconds: float,
    peer: bool = False,
    rounds: int = 1,
) -> dict[str, Any]:
    site = synthetic_building(modules, period_ms)
    async with simulator_process(site) as ready:
        for module in site["modules"]:
            module["port"] = ready["modules"][module["id"]]
        config: BuildingConfig = load_building(site)
        ours: list[dict[str, Any]] = []
        theirs: list[dict[str, Any]] = []
        agree = True
        async with httpx.AsyncClient(base_url=ready["control"], timeout=10) as http:
            windows = rounds * (2 if peer else 1)
            await _hold_pattern(http, modules, windows * (seconds + 3) + 10)
            for _ in range(rounds):  # interleaved: ours, peer, ours, peer, ...
                ours.append(await _ours_window(config, filter_ms, period_ms, seconds))
                if peer:
                    theirs.append(await _peer_window(config, period_ms, seconds))
                    agree = agree and ours[-1]["_last"] == theirs[-1]["_last"]
            await asyncio.sleep(0.5)
            detect, errors = await _detect(config, modules, period_ms, filter_ms, seconds, http)
    for r in (*ours, *theirs):
        del r["_last"]
    mine = _median_runs(ours)
    print(
        f"{modules} modules at {period_ms} ms, filter {filter_ms} ms: {len(detect)} presses "
        f"detected, {mine['overruns']} overruns, {errors} errors; CPU % per run: ours "
        f"{[r['cpu_percent'] for r in ours]}, peer {[r['cpu_percent'] for r in theirs]}",
        file=sys.stderr,
    )
    result: dict[str, Any] = {
        "modules": modules,
        "period_ms": period_ms,
        "jitter_ms": mine["jitter_ms"],
        "period_error_ms": mine["period_error_ms"],
        "drift_ms_per_poll": mine["drift_ms_per_poll"],
        "polls_per_s": mine["polls_per_s"],
        "cpu_percent": mine["cpu_percent"],
        "detect_ms": percentiles(detect, digits=1),
    }
    if rounds > 1:
        result["rounds"] = rounds
    if peer:
        other = _median_runs(theirs)
        result["peer"] = other
        result["ratio"] = {
            "cpu_percent": _ratio(mine["cpu_percent"], other["cpu_percent"]),
            "period_error_p50": _ratio(
                mine["period_error_ms"]["p50"], other["period_error_ms"]["p50"]
            ),
            "period_error_p99": _ratio(
                mine["period_error_ms"]["p99"], other["period_error_ms"]["p99"]
            ),
            "polls_per_s": _ratio(mine["polls_per_s"], other["polls_per_s"]),
        }
        result["agree"] = agree
    return result


def _ratio(a: float | None, b: float | None) -> float | None:
    return round(a / b, 3) if a is not None and b else None


def _loop_factory() -> Callable[[], asyncio.AbstractEventLoop] | None:
    try:
        import uvloop
    except ImportError:
        return None
    return uvloop.new_event_loop


@click.command("modbus")
@click.option("--modules", type=click.IntRange(1, 500), default=50, show_default=True)
@click.option("--period-ms", type=click.IntRange(10, 10_000), default=200, show_default=True)
@click.option("--filter-ms", type=click.FloatRange(0, 5000), default=200.0, show_default=True)
@click.option(
    "--seconds",
    type=click.FloatRange(1, 3600),
    default=10.0,
    show_default=True,
    help="Length of each measured window.",
)
@click.option("--peer", is_flag=True, help="Also run a plain pymodbus loop, interleaved.")
@click.option(
    "--rounds",
    type=click.IntRange(1, 20),
    default=1,
    show_default=True,
    help="CPU windows per contender (medians reported).",
)
@click.option("--json", "as_json", is_flag=True, help="Print only the result line.")
def main(
    modules: int,
    period_ms: int,
    filter_ms: float,
    seconds: float,
    peer: bool,
    rounds: int,
    as_json: bool,
) -> None:
    """Poll N simulated modules: CPU, period accuracy, press detection (and a plain peer)."""
    # The server runs under uvicorn, whose loop is uvloop when installed: measure the same.
    with asyncio.Runner(loop_factory=_loop_factory()) as runner:
        result = runner.run(run(modules, period_ms, filter_ms, seconds, peer, rounds))
    if not as_json:
        click.echo(json.dumps(result, indent=2))
    print_result(result)
