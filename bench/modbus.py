"""BuildingInterface benchmark: polling jitter, CPU and press-to-event latency over real Modbus/TCP.

    guidebot bench modbus --modules 50 --json

The building simulator runs in its own process (``python -m building_sim``) with N modules of
8 buttons each on loopback; this process runs the BuildingInterface on an in-process hub, as the
server does. Last line:
{"modules", "period_ms", "jitter_ms": {"p50", "p99"}, "cpu_percent", "detect_ms": {"p50", "p99"}}

- jitter_ms: how late each poll started against its fixed schedule (start + n x period).
- cpu_percent: CPU time of this process (the BuildingInterface alone, not the simulator) over
  the measured window, in percent of one core.
- detect_ms: from the start of a press (midpoint of the control API call that starts it) to its
  building_input_changed on the hub. Floor: filter + half a period on average (200 + 100 ms).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
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

from backend.building.config import BuildingConfig, load_building
from backend.building.interface import BuildingInterface
from guidebot.benchutil import percentiles, print_result
from guidebot.bus import Bus
from guidebot.messages import Message

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


async def run(modules: int, period_ms: int, filter_ms: float, seconds: float) -> dict[str, Any]:
    site = synthetic_building(modules, period_ms)
    async with simulator_process(site) as ready:
        for module in site["modules"]:
            module["port"] = ready["modules"][module["id"]]
        config: BuildingConfig = load_building(site)
        hub = Bus()
        detected: dict[tuple[str, str], asyncio.Future[float]] = {}
        loop = asyncio.get_running_loop()

        def on_change(message: Message) -> None:
            key = (message.payload["module"], message.payload["point"])
            future = detected.get(key)
            if message.payload["value"] and future is not None and not future.done():
                future.set_result(time.monotonic())

        hub.endpoint("bench").subscribe("building_input_changed", on_change)
        async with (
            BuildingInterface(hub.endpoint("building"), config, filter_ms=filter_ms) as bi,
            httpx.AsyncClient(base_url=ready["control"], timeout=10) as http,
        ):
            deadline = loop.time() + 30
            while not all(p.health.polls > 2 for p in bi.pollers.values()):
                if loop.time() > deadline:
                    raise RuntimeError("modules did not come online within 30 s")
                await asyncio.sleep(0.05)
            for poller in bi.pollers.values():
                poller.jitter_s.clear()
            process = psutil.Process()
            cpu0, wall0 = sum(process.cpu_times()[:2]), loop.time()
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
                    reply = await http.post(
                        f"/buttons/b{module}_{button}/press", json={"ms": press_ms}
                    )
                    reply.raise_for_status()
                    started = (sent + time.monotonic()) / 2
                    with contextlib.suppress(TimeoutError):
                        detect.append((await asyncio.wait_for(future, 5) - started) * 1000)
                    del detected[key]
                    # Let the press end, then a random phase against the poll grid.
                    await asyncio.sleep(press_ms / 1000 + rng.uniform(0.05, period_ms / 1000))

            await asyncio.gather(*(presser(w) for w in range(workers)))
            cpu = sum(process.cpu_times()[:2]) - cpu0
            wall = loop.time() - wall0
            jitter = [j * 1000 for p in bi.pollers.values() for j in p.jitter_s]
            overruns = sum(p.health.overruns for p in bi.pollers.values())
            errors = sum(p.health.errors for p in bi.pollers.values())
    print(
        f"{modules} modules at {period_ms} ms, filter {filter_ms} ms: {len(jitter)} polls,"
        f" {len(detect)} presses detected, {overruns} overruns, {errors} errors",
        file=sys.stderr,
    )
    return {
        "modules": modules,
        "period_ms": period_ms,
        "jitter_ms": percentiles(jitter),
        "cpu_percent": round(cpu / wall * 100, 1),
        "detect_ms": percentiles(detect, digits=1),
    }


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
@click.option("--seconds", type=click.FloatRange(1, 3600), default=20.0, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Print only the result line.")
def main(modules: int, period_ms: int, filter_ms: float, seconds: float, as_json: bool) -> None:
    """Poll N simulated modules; measure poll jitter, CPU and press detection latency."""
    # The server runs under uvicorn, whose loop is uvloop when installed: measure the same.
    with asyncio.Runner(loop_factory=_loop_factory()) as runner:
        result = runner.run(run(modules, period_ms, filter_ms, seconds))
    if not as_json:
        click.echo(json.dumps(result, indent=2))
    print_result(result)
