"""``guidebot bench robot``: the robot agent's reaction time and footprint.

- cmd_to_velocity_frame_ms: a task arriving over the link (task_assigned received by the
  robot's link from the hub) -> the first non-zero velocity frame on the robot's CAN bus. In
  between: RG dispatch starts navigate_to_point, navigation plans on its on-board map (the
  robot runs the server's live site version) and declares the path to the Traffic Manager
  without waiting for its answer, commands the base, the RoboCAN base entity sends the frame.
  The GuideBot paper's T8 -> T14, 772 ms on average. Real server on loopback,
  real agent with simulated RoboCAN modules, time scale 1; the server runs in its own process.
  Consecutive commands (each task cancelled before the next): ``blocks_p50_ms`` gives the p50
  of every block of 25, so a reaction time that degrades as commands accumulate shows up;
  ``stages_p50_ms`` times the on-board messages on the way (task_assigned = 0).
- cpu_percent_idle / cpu_percent_touring / rss_mb: a separate ``guidebot robot --simulate``
  process connected to the same server: its CPU (percent of one core) while idle (waiting net
  running, state at 1 Hz, CAN watchdogs) and while giving a tour, and its resident memory.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import statistics
import tempfile
import threading
import time
import uuid
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
import click
import httpx
import psutil
import yaml

from guidebot.benchutil import percentiles, print_result
from guidebot.processes import guidebot_command

ROOT = Path(__file__).resolve().parent.parent
SITE = ROOT / "sites" / "demo_museum.yaml"


class _FirstMovingFrame(can.Listener):
    """Remembers the wall time of the first velocity frame with a non-zero speed after arm().

    Armed when a task_assigned reaches the robot, with that task's id: a frame caused by some
    other task (an errand of the Task Manager slipping in) is told apart by ``task_id``.
    """

    def __init__(self) -> None:
        self.event = threading.Event()
        self.hit: tuple[str | None, float] | None = None  # (task armed for, frame time)
        self._task_id: str | None = None
        self._armed = False

    def arm(self, task_id: str | None = None) -> None:
        self.hit = None
        self._task_id = task_id
        self.event.clear()
        self._armed = True

    def on_message_received(self, msg: can.Message) -> None:
        from robot_agent.robocan import protocol as p

        if not self._armed or not msg.data or msg.data[0] != p.Op.SET_VELOCITY or msg.dlc < 6:
            return
        if int.from_bytes(msg.data[2:6], "little", signed=True) != 0:
            self._armed = False
            self.hit = (self._task_id, msg.timestamp)
            self.event.set()


def _bench_site(tmp: Path, robots: list[str]) -> Path:
    from guidebot.site.yamlio import load_site_file

    data = load_site_file(SITE).model_dump(mode="json")
    data["robots"] = [r for r in data["robots"] if r["name"] in robots]
    data["modules"] = []  # no building: the path used here crosses no door or elevator
    data["doors"], data["elevators"], data["buttons"] = [], [], []
    data["emergency"]["alarms"] = []  # their inputs are on the building's modules
    path = tmp / "site.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


TRACED = ("run_petri_net", "navigate_to", "get_path", "path", "set_velocity")
"""On-board messages whose first appearance after a task's arrival is timed."""
BLOCK = 25


async def _latency(
    server: Any, site: Path, samples: int, trace: list[dict[str, float]] | None = None
) -> list[float]:
    from robot_agent.agent import AgentConfig, RobotAgent

    channel = f"bench-{uuid.uuid4().hex[:8]}"
    tap = _FirstMovingFrame()
    tap_bus = can.Bus(interface="virtual", channel=channel)
    notifier = can.Notifier(tap_bus, [tap], timeout=0.05)
    config = AgentConfig(
        name="R1",
        server=server.url,
        token="robot-R1-demo-token",
        can=f"virtual:{channel}",
        simulate=True,
        time_scale=1.0,
        start_node="entrance",
        site=site,
        speech_engine=None,
    )
    arrived: dict[str, float] = {}
    results: list[float] = []
    headers = {"Authorization": f"Bearer {server.admin_token}"}
    try:
        async with (
            RobotAgent(config) as agent,
            httpx.AsyncClient(base_url=server.url, headers=headers) as http,
        ):
            assert agent.link is not None and agent.hardware is not None
            assert agent.navigator is not None
            await agent.hardware.stack.wait_online(timeout=30)  # type: ignore[attr-defined]

            def on_down(message: Any) -> None:
                if message.type == "task_assigned":
                    task = str(message.payload.get("task_id"))
                    arrived[task] = time.time()
                    tap.arm(task)

            agent.link.on_message_down = on_down
            stages: dict[str, float] = {}

            def on_any(message: Any) -> None:
                if message.type in TRACED and message.type not in stages:
                    stages[message.type] = time.time()

            if trace is not None:
                tracer = agent.bus.endpoint("bench-trace")
                for traced in TRACED:
                    tracer.subscribe(traced, on_any, tap=True)
            foreign = 0
            while len(results) < samples:
                # A cancelled goal leaves the robot's node unchanged: always ask for the other.
                target = "hall" if agent.navigator.node != "hall" else "entrance"
                await _idle(agent, http)
                tap.arm()
                stages.clear()
                r = await http.post(
                    "/api/tasks",
                    json={"kind": "go_to", "params": {"node": target}, "robot": "R1"},
                )
                r.raise_for_status()
                task_id = r.json()["id"]
                if not await asyncio.to_thread(tap.event.wait, 10.0):
                    tasks = (await http.get("/api/tasks")).json()["tasks"]
                    summary = [(t["kind"], t["state"], t["robot"], t["reason"]) for t in tasks]
                    raise RuntimeError(
                        f"sample {len(results)}: no velocity frame within 10 s: {summary}"
                    )
                hit = tap.hit  # another task (an errand of the Task Manager) moved the robot
                if hit is None or hit[0] != task_id:
                    foreign += 1
                    if foreign > samples:
                        raise RuntimeError("the Task Manager keeps sending the robot on errands")
                    await http.post(f"/api/tasks/{task_id}/cancel", json={"reason": "bench"})
                    continue
                results.append((hit[1] - arrived[task_id]) * 1000.0)
                if trace is not None:
                    t0 = arrived[task_id]
                    trace.append({k: round((v - t0) * 1000, 2) for k, v in stages.items()})
                await http.post(f"/api/tasks/{task_id}/cancel", json={"reason": "bench"})
    finally:
        await asyncio.to_thread(notifier.stop, 1.0)
        tap_bus.shutdown()
    return results


async def _idle(agent: Any, http: httpx.AsyncClient) -> None:
    """Wait until the robot has no main task (cancel the Task Manager's own errands)."""
    deadline = time.monotonic() + 30
    while agent.tasks.current is not None:
        if time.monotonic() > deadline:
            raise RuntimeError("the robot stays busy")
        await http.post(f"/api/tasks/{agent.tasks.current.task_id}/cancel", json={"reason": "x"})
        await asyncio.sleep(0.2)
    await asyncio.sleep(0.3)  # let the cancelled goal unwind and the base come to rest


async def _footprint(server: Any, site: Path, seconds: float) -> dict[str, float]:
    args = guidebot_command("robot", "--name", "R2", "--server", server.url)
    args += ["--token", "robot-R2-demo-token", "--simulate", "--can", "virtual:R2", "--site"]
    args += [str(site), "--start-node", "charge_b", "--log-level", "warning"]
    child = await asyncio.create_subprocess_exec(
        *args, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL
    )
    headers = {"Authorization": f"Bearer {server.admin_token}"}
    try:
        assert child.stdout is not None
        line = await asyncio.wait_for(child.stdout.readline(), 60)
        if b"ready" not in line:
            raise RuntimeError(f"robot process did not start: {line!r}")
        proc = psutil.Process(child.pid)
        await asyncio.sleep(3.0)  # bring-up of the CAN modules done, idle net running
        proc.cpu_percent(None)
        await asyncio.sleep(seconds)
        idle = proc.cpu_percent(None)
        async with httpx.AsyncClient(base_url=server.url, headers=headers) as http:
            r = await http.post(
                "/api/tasks",
                json={"kind": "tour", "params": {"tour": "ground"}, "robot": "R2"},
            )
            r.raise_for_status()
            await asyncio.sleep(1.0)
            proc.cpu_percent(None)
            await asyncio.sleep(seconds)
            touring = proc.cpu_percent(None)
            rss = proc.memory_info().rss / 1e6
        return {"cpu_percent_idle": idle, "cpu_percent_touring": touring, "rss_mb": rss}
    finally:
        child.terminate()
        try:
            await asyncio.wait_for(child.wait(), 15)
        except TimeoutError:
            child.kill()
            await child.wait()


@dataclass
class _Server:
    url: str
    admin_token: str


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@contextlib.asynccontextmanager
async def _server_process(tmp: str, site: Path) -> AsyncIterator[_Server]:
    """The central server in its own process, as deployed: its work never shares the robot's
    event loop (a task's path request still crosses it, over loopback)."""
    port = _free_port()
    args = guidebot_command("server", "--port", str(port), "--site")
    args += [str(site), "--db", f"sqlite+aiosqlite:///{tmp}/bench.db", "--log-level", "warning"]
    child = await asyncio.create_subprocess_exec(
        *args, stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL
    )
    server = _Server(f"http://127.0.0.1:{port}", "dev-admin-token")
    try:
        async with httpx.AsyncClient(base_url=server.url) as http:
            for _ in range(300):
                with contextlib.suppress(httpx.HTTPError):
                    if (await http.get("/api/health")).status_code == 200:
                        break
                if child.returncode is not None:
                    raise RuntimeError("the server process exited at start-up")
                await asyncio.sleep(0.1)
            else:
                raise RuntimeError("the server did not answer within 30 s")
        yield server
    finally:
        child.terminate()
        try:
            await asyncio.wait_for(child.wait(), 15)
        except TimeoutError:
            child.kill()
            await child.wait()


def blocks_p50(samples: list[float], block: int = BLOCK) -> list[float]:
    """p50 of each run of ``block`` consecutive samples (a last partial block included)."""
    return [
        round(statistics.median(samples[i : i + block]), 2) for i in range(0, len(samples), block)
    ]


def stages_p50(trace: list[dict[str, float]]) -> dict[str, float]:
    """p50 time from task_assigned to each traced on-board message, in path order."""
    return {
        name: round(statistics.median(times), 2)
        for name in TRACED
        if (times := [t[name] for t in trace if name in t])
    }


async def _run(samples: int, seconds: float) -> dict[str, Any]:
    trace: list[dict[str, float]] = []
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-robot-") as tmp:
        site = _bench_site(Path(tmp), ["R1", "R2"])
        async with _server_process(tmp, site) as server:
            latencies = await _latency(server, site, samples, trace)
            footprint = await _footprint(server, site, seconds)
    return {
        "cmd_to_velocity_frame_ms": {
            **percentiles(latencies, digits=2),
            "max": round(max(latencies), 2),
            "samples": len(latencies),
        },
        "blocks_p50_ms": blocks_p50(latencies),
        "stages_p50_ms": stages_p50(trace),
        "cpu_percent_idle": round(footprint["cpu_percent_idle"], 2),
        "cpu_percent_touring": round(footprint["cpu_percent_touring"], 2),
        "rss_mb": round(footprint["rss_mb"], 1),
    }


@click.command()
@click.option(
    "--samples",
    type=click.IntRange(min=1),
    default=200,
    show_default=True,
    help="Consecutive commands timed (p99 needs 100+ to be more than the maximum).",
)
@click.option(
    "--seconds",
    type=click.FloatRange(min=1),
    default=10.0,
    show_default=True,
    help="Length of each CPU measurement window.",
)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line on stdout.")
def main(samples: int, seconds: float, as_json: bool) -> None:
    """Task over the link -> first velocity frame on CAN; idle and touring CPU; memory."""
    logging.basicConfig(level=logging.ERROR)
    result = asyncio.run(_run(samples, seconds))
    if not as_json:
        latency = result["cmd_to_velocity_frame_ms"]
        click.echo(
            f"task -> velocity frame: p50 {latency['p50']} ms, p99 {latency['p99']} ms "
            "(paper T8->T14: 772 ms average)"
        )
        click.echo(f"p50 per block of {BLOCK}: {result['blocks_p50_ms']}")
        click.echo(
            f"robot process: idle {result['cpu_percent_idle']}% of a core, touring "
            f"{result['cpu_percent_touring']}%, {result['rss_mb']} MB resident"
        )
    with contextlib.suppress(BrokenPipeError):
        print_result(result)
