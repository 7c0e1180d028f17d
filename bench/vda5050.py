"""VDA 5050 master control benchmark: many vehicles' states through a real Mosquitto into the
hub, and area grants into order updates on the broker.

    guidebot bench vda5050 --robots 200 --movers 4 --seconds 20 --json

A private Mosquitto, a real server (in this process) on a line of ten nodes with the area
``corridor`` in the middle, and, in another process (bench/vda5050_load.py), ``--robots``
vehicles that report ``state`` at 1 Hz each on one MQTT connection, plus ``--movers`` simulated
vehicles driving go-tos end to end through the corridor (pinned tasks, one after another).

Last line: {"robots", "movers", "seconds", "states", "state_to_hub_ms" {p50, p99},
"grants", "grant_to_order_ms" {p50, p99}, "server_cpu_percent", "refused"}.
state_to_hub_ms: the state's own timestamp (ms, set when the load process sends it) to its
``robot_state`` on the hub (a tap in the server). grant_to_order_ms: ``area_granted`` for a
mover on the hub to the order update (orderUpdateId > 0) reaching a subscriber of the broker.
server_cpu_percent: this process (server, tap, subscriber) over the measured window, in % of
one core.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import aiomqtt
import click
import httpx
import psutil
import yaml

from backend.settings import Settings
from backend.testing import running_server
from bench.vda5050_load import MANUFACTURER, serial
from guidebot.benchutil import percentiles, print_result
from guidebot.demo_vda import mosquitto_binary, start_broker
from guidebot.messages import Message

NODES = [f"n{i}" for i in range(10)]


def _site(count: int) -> dict[str, Any]:
    return {
        "name": "VDA 5050 bench line",
        "floors": [{"id": "F0", "name": "Ground", "level": 0}],
        "nodes": [{"id": n, "floor": "F0", "x": 4.0 * i, "y": 0.0} for i, n in enumerate(NODES)],
        "edges": [{"a": a, "b": b} for a, b in itertools.pairwise(NODES)],
        "areas": [{"id": "corridor", "nodes": ["n4", "n5"]}],
        "robots": [
            {
                "name": serial(i),
                "token": f"robot-{serial(i)}-bench-token",
                "start_node": "n0",
                "interface": "vda5050",
                "manufacturer": MANUFACTURER,
                "serial_number": serial(i),
            }
            for i in range(count)
        ],
    }


@click.command()
@click.option("--robots", type=click.IntRange(1, 5000), default=200, show_default=True)
@click.option("--movers", type=click.IntRange(0, 50), default=4, show_default=True)
@click.option("--seconds", type=click.FloatRange(min=1), default=20.0, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line.")
def main(robots: int, movers: int, seconds: float, as_json: bool) -> None:
    """States of --robots vehicles into the hub, grants into order updates."""
    binary = mosquitto_binary()
    if binary is None:
        raise click.ClickException("mosquitto is not installed (Debian mosquitto)")
    result = asyncio.run(_run(binary, robots, movers, seconds))
    if not as_json:
        click.echo(
            f"{robots} reporting + {movers} moving vehicles, {seconds:g} s: "
            f"state_to_hub_ms {result['state_to_hub_ms']}, grant_to_order_ms "
            f"{result['grant_to_order_ms']} ({result['grants']} grants), server CPU "
            f"{result['server_cpu_percent']} %"
        )
    print_result(result)


async def _run(binary: str, robots: int, movers: int, seconds: float) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-vda-") as root:
        folder = Path(root)
        broker, url = start_broker(binary, folder)
        load: asyncio.subprocess.Process | None = None
        try:
            site = folder / "site.yaml"
            site.write_text(yaml.safe_dump(_site(robots + movers)), encoding="utf-8")
            settings = Settings(
                db_url=f"sqlite+aiosqlite:///{folder / 'bench.db'}",
                site=site,
                building_enabled=False,
                mqtt_url=url,
                log_level="warning",
            )
            async with running_server(settings) as server:
                args = [sys.executable, "-m", "bench.vda5050_load", "--broker", url]
                args += ["--robots", str(robots), "--movers", str(movers)]
                load = await asyncio.create_subprocess_exec(*args, stdout=asyncio.subprocess.PIPE)
                return await _measure(server, url, load, robots, movers, seconds)
        finally:
            if load is not None and load.returncode is None:
                load.kill()
                await load.wait()
            broker.kill()
            broker.wait(10)


async def _measure(
    server: Any,
    url: str,
    load: asyncio.subprocess.Process,
    robots: int,
    movers: int,
    seconds: float,
) -> dict[str, Any]:
    state = server.app.state
    master, tm = state.vda5050, state.task_manager
    by_name = {r.name: r for r in master.robots.values()}
    moving = {serial(robots + i) for i in range(movers)}
    latencies: list[float] = []
    grants: dict[str, float] = {}
    grant_ms: list[float] = []
    measuring = False

    def tap(message: Message) -> None:
        now = time.time()
        if not measuring:
            return
        if message.type == "robot_state":
            robot = by_name.get(message.payload["robot"])
            sent = (robot.state or {}).get("timestamp") if robot else None
            if sent and message.payload["robot"] not in moving:
                latencies.append((now - datetime.fromisoformat(sent).timestamp()) * 1000)
        elif message.type == "area_granted" and message.payload["robot"] in moving:
            grants[message.payload["robot"]] = now

    state.hub.endpoint("bench_tap").subscribe("*", tap, tap=True)
    assert load.stdout is not None
    line = await load.stdout.readline()
    if line.strip() != b"ready":
        raise click.ClickException(f"the load process did not start: {line!r}")
    names = [serial(i) for i in range(robots + movers)]
    deadline = time.monotonic() + 60
    while not all(tm.robots[n].online for n in names):
        if time.monotonic() > deadline:
            late = [n for n in names if not tm.robots[n].online]
            raise click.ClickException(f"{len(late)} vehicles not online after 60 s")
        await asyncio.sleep(0.1)
    address = url.removeprefix("mqtt://").split(":")
    async with (
        aiomqtt.Client(address[0], int(address[1]), identifier="bench-orders") as orders,
        httpx.AsyncClient(
            base_url=server.url, headers={"Authorization": f"Bearer {server.admin_token}"}
        ) as http,
    ):
        await orders.subscribe(f"uagv/v2/{MANUFACTURER}/+/order", qos=1)

        async def read_orders() -> None:
            async for message in orders.messages:
                now = time.time()
                body = json.loads(bytes(message.payload))  # type: ignore[arg-type]
                robot = body["serialNumber"]
                if body["orderUpdateId"] > 0 and robot in grants:
                    grant_ms.append((now - grants.pop(robot)) * 1000)

        async def drive() -> None:
            while True:
                for name in sorted(moving):
                    robot = tm.robots[name]
                    if robot.current is None and robot.online:
                        goal = "n9" if robot.node != "n9" else "n0"
                        body = {"kind": "go_to", "params": {"node": goal}, "robot": name}
                        await http.post("/api/tasks", json=body)
                await asyncio.sleep(0.2)

        reader = asyncio.create_task(read_orders())
        driver = asyncio.create_task(drive())
        process = psutil.Process()
        cpu0, wall0 = process.cpu_times(), time.monotonic()
        measuring = True
        await asyncio.sleep(seconds)
        measuring = False
        cpu1, wall1 = process.cpu_times(), time.monotonic()
        for task in (reader, driver):
            task.cancel()
        await asyncio.gather(reader, driver, return_exceptions=True)
    cpu = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / (wall1 - wall0) * 100
    return {
        "robots": robots,
        "movers": movers,
        "seconds": seconds,
        "states": len(latencies),
        "state_to_hub_ms": percentiles(latencies),
        "grants": len(grant_ms),
        "grant_to_order_ms": percentiles(grant_ms),
        "server_cpu_percent": round(cpu, 1),
        "refused": master.refused,
    }
