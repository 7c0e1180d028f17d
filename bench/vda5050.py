"""VDA 5050 master control benchmark: many vehicles' states through a real Mosquitto into the
hub, and area grants into order updates on the broker.

    guidebot bench vda5050 --robots 200 --movers 4 --guidebot 4 --seconds 20 --json

A private Mosquitto, a real server (in this process) on a line of ten nodes with the area
``corridor`` in the middle, and, in another process (bench/vda5050_load.py), ``--robots``
vehicles that report ``state`` at 1 Hz each on one MQTT connection, plus ``--movers`` simulated
vehicles driving go-tos end to end through the corridor (pinned tasks, one after another),
and ``--guidebot`` GuideBot robots (hub clients over the server's real WebSocket, in the
bench's process) that report ``robot_state`` at 1 Hz each: the same measure for our own robots
in the same run, so the ratio says what VDA 5050 costs on a loaded machine.

Last line: {"robots", "movers", "seconds", "states", "state_to_hub_ms" {p50, p99},
"grants", "grant_to_order_ms" {p50, p99}, "server_cpu_percent", "refused", "guidebot",
"guidebot_states", "guidebot_state_to_hub_ms" {p50, p99}, "state_ratio" {p50, p99}
(VDA 5050 / GuideBot), "master_to_hub_ms" {p50, p99}, "master_ratio" {p50, p99},
"load_average" (1 min, at the start and the end)}.
master_to_hub_ms: the master control's own share of state_to_hub_ms: a state handed over by
the MQTT session (in the server's process) to its ``robot_state`` on the hub. On a loaded
machine state_to_hub_ms is mostly the load process's and the broker's queues (the load
process is starved of CPU like any other); master_to_hub_ms against a GuideBot robot's
state_to_hub_ms in the same process is the fair comparison.
guidebot_state_to_hub_ms: a GuideBot robot's ``robot_state`` published by its hub client to
its arrival at the hub's tap (both in this process: the same clock).
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
import os
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
from guidebot.client import HubClient
from guidebot.demo_vda import mosquitto_binary, start_broker
from guidebot.messages import Message
from guidebot.payloads.robot import RobotMode, RobotState
from guidebot.vda5050.mqtt import NO_DELAY

NODES = [f"n{i}" for i in range(10)]


def _guidebot_name(i: int) -> str:
    return f"G{i:02d}"


def _site(count: int, guidebot: int = 0) -> dict[str, Any]:
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
        ]
        + [
            {
                "name": _guidebot_name(i),
                "token": f"robot-{_guidebot_name(i)}-bench-token",
                "start_node": "n0",
            }
            for i in range(guidebot)
        ],
    }


@click.command()
@click.option("--robots", type=click.IntRange(1, 5000), default=200, show_default=True)
@click.option("--movers", type=click.IntRange(0, 50), default=4, show_default=True)
@click.option(
    "--guidebot",
    type=click.IntRange(0, 200),
    default=4,
    show_default=True,
    help="GuideBot robots reporting at 1 Hz over the hub's WebSocket, for comparison.",
)
@click.option("--seconds", type=click.FloatRange(min=1), default=20.0, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line.")
def main(robots: int, movers: int, guidebot: int, seconds: float, as_json: bool) -> None:
    """States of --robots vehicles into the hub, grants into order updates."""
    binary = mosquitto_binary()
    if binary is None:
        raise click.ClickException("mosquitto is not installed (Debian mosquitto)")
    load0 = os.getloadavg()[0]
    result = asyncio.run(_run(binary, robots, movers, seconds, guidebot))
    result["load_average"] = {"start": round(load0, 2), "end": round(os.getloadavg()[0], 2)}
    if not as_json:
        click.echo(
            f"{robots} reporting + {movers} moving vehicles, {seconds:g} s: "
            f"state_to_hub_ms {result['state_to_hub_ms']}, grant_to_order_ms "
            f"{result['grant_to_order_ms']} ({result['grants']} grants), server CPU "
            f"{result['server_cpu_percent']} %; {guidebot} GuideBot robots: state_to_hub_ms "
            f"{result['guidebot_state_to_hub_ms']} (VDA / GuideBot {result['state_ratio']})"
        )
    print_result(result)


async def _run(
    binary: str, robots: int, movers: int, seconds: float, guidebot: int = 0
) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-vda-") as root:
        folder = Path(root)
        broker, url = start_broker(binary, folder)
        load: asyncio.subprocess.Process | None = None
        try:
            site = folder / "site.yaml"
            site.write_text(yaml.safe_dump(_site(robots + movers, guidebot)), encoding="utf-8")
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
                return await _measure(server, url, load, robots, movers, seconds, guidebot)
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
    guidebot: int = 0,
) -> dict[str, Any]:
    state = server.app.state
    master, tm = state.vda5050, state.task_manager
    by_name = {r.name: r for r in master.robots.values()}
    moving = {serial(robots + i) for i in range(movers)}
    latencies: list[float] = []
    grants: dict[str, float] = {}
    grant_ms: list[float] = []
    ours: list[float] = []
    sent_at: dict[tuple[str, int], float] = {}
    master_ms: list[float] = []
    got: dict[str, float] = {}
    on_message = master.session.on_message

    def received(topic: str, payload: bytes) -> None:
        """The master's share: a state taken from the MQTT session (in this process)."""
        if measuring and topic.endswith("/state"):
            got[topic.split("/")[3]] = time.time()
        on_message(topic, payload)

    master.session.on_message = received
    measuring = False

    def tap(message: Message) -> None:
        now = time.time()
        if not measuring:
            return
        if message.type == "robot_state" and message.payload["robot"] not in by_name:
            at = sent_at.pop((message.payload["robot"], message.payload.get("seq", -1)), None)
            if at is not None:
                ours.append((now - at) * 1000)
        elif message.type == "robot_state":
            robot = by_name.get(message.payload["robot"])
            sent = (robot.state or {}).get("timestamp") if robot else None
            if sent and message.payload["robot"] not in moving:
                latencies.append((now - datetime.fromisoformat(sent).timestamp()) * 1000)
            if (at := got.pop(message.payload["robot"], None)) is not None:
                master_ms.append((now - at) * 1000)
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
        aiomqtt.Client(
            address[0], int(address[1]), identifier="bench-orders", socket_options=NO_DELAY
        ) as orders,
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

        clients = [
            HubClient(server.ws_url, f"robot-{_guidebot_name(i)}-bench-token")
            for i in range(guidebot)
        ]
        for client in clients:
            await client.start()
        for client in clients:
            await asyncio.wait_for(client.connected.wait(), 30)

        async def report(i: int, client: HubClient) -> None:
            """A GuideBot robot's robot_state at 1 Hz (spread over the second)."""
            name = _guidebot_name(i)
            await asyncio.sleep(i / max(1, guidebot))
            for seq in itertools.count(1):
                sent_at[(name, seq)] = time.time()
                client.publish(RobotState(robot=name, node="n0", mode=RobotMode.IDLE, seq=seq))
                await asyncio.sleep(1.0)

        reporters = [asyncio.create_task(report(i, c)) for i, c in enumerate(clients)]
        reader = asyncio.create_task(read_orders())
        driver = asyncio.create_task(drive())
        process = psutil.Process()
        cpu0, wall0 = process.cpu_times(), time.monotonic()
        measuring = True
        await asyncio.sleep(seconds)
        measuring = False
        cpu1, wall1 = process.cpu_times(), time.monotonic()
        for task in (reader, driver, *reporters):
            task.cancel()
        await asyncio.gather(reader, driver, *reporters, return_exceptions=True)
        for client in clients:
            await client.close()
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
        "master_to_hub_ms": percentiles(master_ms),
        "guidebot": guidebot,
        "guidebot_states": len(ours),
        "guidebot_state_to_hub_ms": percentiles(ours),
        "state_ratio": _ratio(percentiles(latencies), percentiles(ours)),
        "master_ratio": _ratio(percentiles(master_ms), percentiles(ours)),
    }


def _ratio(vda: Any, ours: Any) -> dict[str, float | None]:
    """VDA 5050's p50 and p99 over GuideBot's (None without both)."""
    out: dict[str, float | None] = {}
    for key in ("p50", "p99"):
        a = vda.get(key) if isinstance(vda, dict) else None
        b = ours.get(key) if isinstance(ours, dict) else None
        out[key] = round(a / b, 2) if a is not None and b else None
    return out
