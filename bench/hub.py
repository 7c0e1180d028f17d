"""Benchmark of the hub: N robots publish robot_state at HZ, M GUIs subscribe to all of it.

``guidebot bench hub --robots 1000 --rate 5 --guis 5 --seconds 15 --json``

Every party is a real process speaking the real WebSocket protocol through ``HubClient``:
- the server (``create_app`` on 127.0.0.1, port 0, hub only unless ``--full-app``) runs in its
  own process so its CPU can be read with psutil;
- the robots are split over ``--robot-procs`` processes; each robot publishes robot_state with a
  sequence number at ``rate`` Hz, phases spread evenly;
- the GUIs share one process and subscribe to ``robot_state``.

Latency = publish (envelope timestamp) to receipt at a GUI, over the measured window (after a
1 s warm-up). "dropped" counts states a GUI never received minus those the hub superseded on
purpose (the overflow rule: newest robot_state replaces the queued one); it should be 0.

On stderr, each process (server, GUIs, each robot process) reports its event-loop lag (p50,
p99, max of a 5 ms ticker) and its garbage collections during the window, then the objects the
collector tracks and what one full collection of them costs; the GUIs list the seconds of the
window whose worst latency passed 100 ms. So a bad p99 says where it came from: the server, a
starved bench process, or a collector pause. The robot and GUI processes freeze their start-up
and connection objects (``gc.freeze``) once connected: one of them holds hundreds of robots'
connections, a real robot holds one. ``BENCH_NO_GC_FREEZE=1`` runs the server without the
hub's GC policy (backend/hub/memory.py), for comparison.

The last line printed is one JSON object with the keys of issue 2.
"""

from __future__ import annotations

import argparse
import array
import asyncio
import contextlib
import gc
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import click
import orjson

from guidebot.benchutil import percentiles, print_result

GUI_TOKEN = "bench-gui-token"
SLOW_GUI = "slowgui"
WARMUP_S = 1.0


def robot_name(i: int) -> str:
    return f"R{i + 1}"


def robot_token(i: int) -> str:
    return f"bench-robot-{i + 1}-token"


def _log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


class Probe:
    """Health of one bench process: event-loop lag and garbage-collector pauses.

    Lag: a task asks to wake every ``tick`` seconds and records how late it woke. A lagging robot
    or GUI process adds its lag to the measured latency, so each process reports its own. GC:
    collections per generation with their CPU time and longest wall-clock pause, the objects the
    collector still tracks at the end and how long one full collection of them takes (timed
    after the measured window).
    """

    def __init__(self, tick: float = 0.005) -> None:
        self.tick = tick
        self.lags: list[float] = []
        self.gc_count = [0, 0, 0]
        self.gc_cpu = [0.0, 0.0, 0.0]
        self.gc_max = 0.0
        self._gc_start = (0.0, 0.0)
        self._task: asyncio.Task[None] | None = None

    def _on_gc(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._gc_start = (time.perf_counter(), time.thread_time())
            return
        wall, cpu = self._gc_start
        generation = info["generation"]
        self.gc_count[generation] += 1
        self.gc_cpu[generation] += time.thread_time() - cpu
        self.gc_max = max(self.gc_max, time.perf_counter() - wall)

    def start(self, freeze: bool = False) -> None:
        """Start sampling; ``freeze``: move everything alive now out of the collector's way.

        A robot process of the bench holds hundreds of robots' connections in one heap (a real
        robot holds one): a full collection there takes 100+ ms and would count as hub latency.
        """
        if freeze:
            gc.collect()
            gc.freeze()
        gc.callbacks.append(self._on_gc)
        self._task = asyncio.create_task(self._run())

    async def _run(self) -> None:
        while True:
            due = time.perf_counter() + self.tick
            await asyncio.sleep(self.tick)
            self.lags.append(time.perf_counter() - due)

    def reset(self) -> None:
        self.lags.clear()
        self.gc_count = [0, 0, 0]
        self.gc_cpu = [0.0, 0.0, 0.0]
        self.gc_max = 0.0

    def report(self) -> dict[str, Any]:
        if self._task is not None:
            self._task.cancel()
        with contextlib.suppress(ValueError):
            gc.callbacks.remove(self._on_gc)
        return {
            "lag_ms": {
                **percentiles([x * 1000 for x in self.lags], 1),
                "max": round(1000 * max(self.lags, default=0.0), 1),
            },
            "gc": {
                "collections": self.gc_count,
                "cpu_ms": [round(1000 * c, 1) for c in self.gc_cpu],
                "max_pause_ms": round(1000 * self.gc_max, 1),
            },
        }

    @staticmethod
    def full_collection(report: dict[str, Any]) -> dict[str, Any]:
        """Add the tracked objects and the time of one full collection (run it after the
        measured window: it stalls the process)."""
        t0 = time.perf_counter()
        gc.collect()
        report["gc"]["full_collection_ms"] = round(1000 * (time.perf_counter() - t0), 1)
        report["gc"]["tracked_objects"] = len(gc.get_objects())
        return report


# -- worker processes ----------------------------------------------------------------------------
async def _serve(robots: int, full_app: bool, peer: bool) -> None:
    """Server process (the hub, or with ``peer`` the plain broadcast): print the bound port,
    then serve until killed."""
    import backend.app
    from backend.auth import Role
    from backend.settings import Settings, StaticToken
    from backend.testing import running_server

    from .hub_peer import create_peer_app

    if not full_app:
        backend.app.COMPONENTS = []
    tokens = [StaticToken(token=GUI_TOKEN, name="gui", role=Role.GUI)]
    tokens += [
        StaticToken(token=robot_token(i), name=robot_name(i), role=Role.ROBOT)
        for i in range(robots)
    ]
    settings = Settings(
        tokens=tokens, db_url=f"sqlite+aiosqlite:///{os.getcwd()}/.bench-hub-{os.getpid()}.db"
    )
    app = create_peer_app() if peer else None
    async with running_server(settings, app=app) as server:
        if os.environ.get("BENCH_NO_GC_FREEZE") and not peer:  # the hub without its GC policy
            server.app.state.hub.memory.enabled = False
        print(f"PORT {server.port}", flush=True)
        probe = Probe()
        probe.start()
        start_at = await _read_start_time()
        seconds = await _read_start_time()
        await asyncio.sleep(max(0.0, start_at + WARMUP_S - time.time()))
        probe.reset()
        await asyncio.sleep(max(0.0, start_at + seconds - time.time()))
        health = probe.report()
        await _read_start_time()  # the GUIs are done
        print(json.dumps(Probe.full_collection(health)), flush=True)
        await asyncio.Event().wait()


async def _read_start_time() -> float:
    line = await asyncio.get_running_loop().run_in_executor(None, sys.stdin.readline)
    return float(line)


def _encode(message: Any) -> str:
    """A message as HubClient puts it on the wire."""
    from pydantic_core import to_jsonable_python

    return orjson.dumps(message.__dict__, default=to_jsonable_python).decode()


async def _drain(ws: Any, errors: list[int]) -> None:
    """Read what the server sends a robot (welcome, errors) so its buffers never fill."""
    with contextlib.suppress(Exception):
        async for frame in ws:
            if b'"error"' in (frame if isinstance(frame, bytes) else frame.encode()):
                errors[0] += 1


async def _robots(url: str, first: int, count: int, rate: float, peer: bool) -> None:
    """Robot process: connect ``count`` robots, wait for the start time, publish, report.

    The same plain ``websockets`` client against both servers: one connection per robot, each
    robot_state sent as HubClient sends it (one frame, the JSON envelope).
    """
    from websockets.asyncio.client import connect

    from guidebot.messages import Message

    async def open_one(i: int) -> Any:
        headers = None if peer else {"Authorization": f"Bearer {robot_token(i)}"}
        return await connect(url, additional_headers=headers, open_timeout=60, ping_interval=None)

    sockets: list[Any] = []
    for start in range(first, first + count, 50):  # in waves: the accept queue is finite
        end = min(first + count, start + 50)
        sockets += await asyncio.gather(*(open_one(i) for i in range(start, end)))
    errors = [0]
    drains = [asyncio.create_task(_drain(ws, errors)) for ws in sockets]
    probe = Probe()
    probe.start(freeze=True)
    print("READY", flush=True)
    start_at = await _read_start_time()
    seconds = await _read_start_time()
    end_at = start_at + seconds
    probe.reset()
    period = 1.0 / rate
    cpu0, t0 = time.process_time(), time.monotonic()
    published = [0] * count

    async def run(k: int, ws: Any) -> None:
        next_at = start_at + period * k / count
        seq = 0
        name = robot_name(first + k)
        while next_at < end_at:
            delay = next_at - time.time()
            if delay > 0:
                await asyncio.sleep(delay)
            seq += 1
            payload = {"robot": name, "x": 1.0, "y": 2.0, "theta": 0.5, "battery": 0.8, "seq": seq}
            await ws.send(_encode(Message(type="robot_state", source=name, payload=payload)))
            next_at += period
        published[k] = seq

    await asyncio.gather(*(run(k, ws) for k, ws in enumerate(sockets)))
    cpu_percent = 100 * (time.process_time() - cpu0) / (time.monotonic() - t0)
    health = probe.report()
    Probe.full_collection(health)
    await asyncio.gather(*(ws.close() for ws in sockets), return_exceptions=True)
    for task in drains:
        task.cancel()
    result = {"published": sum(published), "errors": errors[0], "cpu": cpu_percent, **health}
    print(json.dumps(result), flush=True)


class _Gui:
    """One GUI connection: frames and robot_state receipts, latency, sequence gaps."""

    def __init__(self, window: list[float], latencies: array.array[float], slow_s: float) -> None:
        self.window = window
        self.latencies = latencies
        self.slow_s = slow_s
        self.frames = 0
        self.received = 0
        self.gaps = 0
        self.last_frame = time.monotonic()
        self.seqs: dict[str, int] = {}
        self.slow: dict[int, float] = {}  # second of the window -> worst latency over 100 ms

    async def read(self, ws: Any) -> None:
        window, latencies, seqs = self.window, self.latencies, self.seqs
        with contextlib.suppress(Exception):
            async for frame in ws:
                now = time.time()
                self.last_frame = time.monotonic()
                self.frames += 1
                data = orjson.loads(frame)
                for message in data if isinstance(data, list) else (data,):
                    if message.get("type") != "robot_state":
                        continue
                    self.received += 1
                    payload = message["payload"]
                    robot, seq = payload["robot"], payload["seq"]
                    previous = seqs.get(robot, 0)
                    if seq > previous + 1:
                        self.gaps += seq - previous - 1
                    seqs[robot] = seq
                    stamp = message["timestamp"]
                    if window[0] <= stamp <= window[1]:
                        latency = now - stamp
                        latencies.append(latency)
                        if latency > 0.1:
                            second = int(stamp - window[0])
                            self.slow[second] = max(self.slow.get(second, 0.0), latency)
                if self.slow_s and now < window[1]:
                    await asyncio.sleep(self.slow_s)  # the deliberately slow GUI


async def _open_gui(url: str, peer: bool, token: str, name: str | None = None) -> Any:
    """Connect a GUI; on the hub, subscribe to robot_state and wait until it is applied."""
    from websockets.asyncio.client import connect

    from guidebot.messages import Message

    if peer:
        return await connect(f"{url}/gui", ping_interval=None)
    query = f"?name={name}" if name else ""
    ws = await connect(
        url + query, additional_headers={"Authorization": f"Bearer {token}"}, ping_interval=None
    )
    await ws.send(_encode(Message(type="subscribe", payload={"patterns": ["robot_state"]})))
    ping = Message(type="ping")
    await ws.send(_encode(ping))
    async with asyncio.timeout(30):
        while ping.id.encode() not in (await ws.recv(decode=False)):
            pass
    return ws


async def _guis(
    url: str, guis: int, admin_url: str, admin_token: str, peer: bool, slow_ms: float
) -> None:
    """GUI process: ``guis`` GUIs (and one slow GUI when ``slow_ms``) read every robot_state."""
    import httpx

    window = [0.0, 0.0]
    latencies: array.array[float] = array.array("d")  # not a list: keeps full GCs cheap
    readers = [_Gui(window, latencies, 0.0) for _ in range(guis)]
    sockets = [await _open_gui(url, peer, GUI_TOKEN) for _ in range(guis)]
    slow_latencies: array.array[float] = array.array("d")
    if slow_ms > 0:
        readers.append(_Gui(window, slow_latencies, slow_ms / 1000))
        sockets.append(await _open_gui(url, peer, admin_token, SLOW_GUI))
    tasks = [asyncio.create_task(g.read(ws)) for g, ws in zip(readers, sockets, strict=True)]
    probe = Probe()
    probe.start(freeze=True)
    print("READY", flush=True)
    start_at = await _read_start_time()
    seconds = await _read_start_time()
    window[0], window[1] = start_at + WARMUP_S, start_at + seconds
    await asyncio.sleep(max(0.0, window[0] - time.time()))
    probe.reset()
    for g in readers:
        g.frames = 0
    received0 = [g.received for g in readers]
    cpu0, t0 = time.process_time(), time.monotonic()
    await asyncio.sleep(max(0.0, window[1] - time.time()))
    cpu_percent = 100 * (time.process_time() - cpu0) / (time.monotonic() - t0)
    frames = [g.frames for g in readers]
    window_received = [g.received - r0 for g, r0 in zip(readers, received0, strict=True)]
    health = probe.report()
    await _read_start_time()  # the robots are done
    for _ in range(300):  # until every GUI has had a quiet second (all delivered), max 60 s
        if all(time.monotonic() - g.last_frame >= 1.0 for g in readers):
            break
        await asyncio.sleep(0.2)
    superseded = {"gui": 0, SLOW_GUI: 0}
    if not peer:
        async with httpx.AsyncClient() as http:
            reply = await http.get(f"{admin_url}/api/hub/clients", params={"token": admin_token})
        for c in reply.json()["clients"]:
            who = SLOW_GUI if c["name"] == SLOW_GUI else "gui"
            if c["name"].startswith("gui") or c["name"] == SLOW_GUI:
                superseded[who] += c["superseded"]
    for ws in sockets:
        await ws.close()
    for task in tasks:
        task.cancel()
    Probe.full_collection(health)
    normal = readers[:guis]
    result: dict[str, Any] = {
        "received": sum(g.received for g in normal),
        "window_received": sum(window_received[:guis]),
        "frames": sum(frames[:guis]),
        "gaps": sum(g.gaps for g in normal),
        "superseded": superseded["gui"],
        "latency_ms": percentiles([x * 1000 for x in latencies]),
        "latency_samples": len(latencies),
        "cpu_percent": round(cpu_percent, 1),
        "slow_seconds": {k: round(v * 1000) for g in normal for k, v in sorted(g.slow.items())},
        **health,
    }
    if slow_ms > 0:
        slow = readers[-1]
        result["slow_gui"] = {
            "read_delay_ms": slow_ms,
            "received": slow.received,
            "superseded": superseded[SLOW_GUI],
            "frames": frames[-1],
            "latency_ms": percentiles([x * 1000 for x in slow_latencies]),
        }
    print(json.dumps(result), flush=True)


# -- orchestration -------------------------------------------------------------------------------
def _spawn(args: Sequence[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "bench.hub", *args],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        bufsize=1,
    )


def _expect(proc: subprocess.Popen[str], prefix: str) -> str:
    assert proc.stdout is not None
    while True:
        line = proc.stdout.readline()
        if not line:
            raise RuntimeError(f"worker exited before printing {prefix!r} (rc={proc.wait()})")
        if line.startswith(prefix):
            return line.strip()


def _tell(procs: Sequence[subprocess.Popen[str]], value: float) -> None:
    for p in procs:
        assert p.stdin is not None
        p.stdin.write(f"{value}\n")
        p.stdin.flush()


def run_benchmark(
    robots: int,
    rate: float,
    guis: int,
    seconds: float,
    robot_procs: int,
    full_app: bool,
    peer: bool = False,
    slow_gui_ms: float = 0.0,
) -> dict[str, Any]:
    """One run against the hub, or with ``peer`` against the plain FastAPI broadcast."""
    import psutil

    who = "peer" if peer else "hub"
    flags = (["--full-app"] if full_app else []) + (["--peer"] if peer else [])
    server = _spawn(["server", "--robots", str(robots), *flags])
    workers: list[subprocess.Popen[str]] = []
    try:
        port = int(_expect(server, "PORT").split()[1])
        url = f"ws://127.0.0.1:{port}/ws"
        _log(f"{who}: server pid {server.pid} on port {port}")
        from backend.settings import DEFAULT_ADMIN_TOKEN

        peer_flag = ["--peer"] if peer else []
        gui_proc = _spawn(
            [
                "guis",
                *("--url", url, "--guis", str(guis), "--slow-ms", str(slow_gui_ms)),
                *("--admin-url", f"http://127.0.0.1:{port}", "--admin-token", DEFAULT_ADMIN_TOKEN),
                *peer_flag,
            ]
        )
        workers.append(gui_proc)
        _expect(gui_proc, "READY")
        procs = max(1, min(robot_procs, robots))
        robot_workers = []
        robot_url = f"{url}/robot" if peer else url
        for p in range(procs):
            first = robots * p // procs
            count = robots * (p + 1) // procs - first
            proc = _spawn(
                [
                    "robots",
                    *("--url", robot_url, "--first", str(first)),
                    *("--count", str(count), "--rate", str(rate), *peer_flag),
                ]
            )
            robot_workers.append(proc)
            workers.append(proc)
        for proc in robot_workers:
            _expect(proc, "READY")
        _log(f"{who}: {robots} robots and {guis} GUIs connected; running {seconds} s")
        start_at = time.time() + 0.5
        _tell([server, gui_proc, *robot_workers], start_at)
        _tell([server, gui_proc, *robot_workers], seconds)
        server_ps = psutil.Process(server.pid)
        time.sleep(max(0.0, start_at + WARMUP_S - time.time()))
        cpu_before = server_ps.cpu_times()
        t0 = time.monotonic()
        time.sleep(max(0.0, start_at + seconds - time.time()))
        cpu_after = server_ps.cpu_times()
        elapsed = time.monotonic() - t0
        busy = (cpu_after.user - cpu_before.user) + (cpu_after.system - cpu_before.system)
        robot_results = [json.loads(_expect(proc, "{")) for proc in robot_workers]
        _tell([gui_proc], 0)
        gui_result = json.loads(_expect(gui_proc, "{"))
        _tell([server], 0)
        server_health = json.loads(_expect(server, "{"))
    finally:
        for proc in [*workers, server]:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            proc.wait()
    for leftover in os.listdir("."):
        if leftover.startswith(f".bench-hub-{server.pid}.db"):
            os.remove(leftover)
    published = sum(r["published"] for r in robot_results)
    expected = published * guis
    dropped = max(0, expected - gui_result["received"] - gui_result["superseded"])
    window = seconds - WARMUP_S
    _log(
        f"{who}: published {published}, GUI receipts {gui_result['received']} of {expected}, "
        f"superseded {gui_result['superseded']}, seq gaps {gui_result['gaps']}, "
        f"refused {sum(r['errors'] for r in robot_results)}, frames to GUIs "
        f"{gui_result['frames']}, latency samples {gui_result['latency_samples']}; CPU % GUI "
        f"process {gui_result['cpu_percent']}, robot processes "
        f"{[round(r['cpu']) for r in robot_results]}"
    )
    if gui_result["slow_seconds"]:
        _log(f"{who}: seconds with latency over 100 ms (worst ms): {gui_result['slow_seconds']}")
    for part, health in [
        ("server", server_health),
        ("guis", gui_result),
        *((f"robots{k}", r) for k, r in enumerate(robot_results)),
    ]:
        _log(f"{who} {part}: loop lag ms {health['lag_ms']}, gc {health['gc']}")
    result: dict[str, Any] = {
        "robots": robots,
        "rate_hz": rate,
        "guis": guis,
        "msgs_in_per_s": round(published / seconds, 1),
        "msgs_out_per_s": round(gui_result["received"] / seconds, 1),
        "frames_out_per_s": round(gui_result["frames"] / window, 1),
        "msgs_per_frame": round(gui_result["window_received"] / max(1, gui_result["frames"]), 2),
        "latency_ms": gui_result["latency_ms"],
        "dropped": dropped,
        "refused": sum(r["errors"] for r in robot_results),
        "server_cpu_percent": round(100.0 * busy / elapsed, 1),
    }
    if "slow_gui" in gui_result:
        result["slow_gui"] = gui_result["slow_gui"]
    return result


RATIO_KEYS = {
    "latency_p50": ("latency_ms", "p50"),
    "latency_p99": ("latency_ms", "p99"),
    "server_cpu_percent": ("server_cpu_percent",),
    "frames_out_per_s": ("frames_out_per_s",),
}
"""Ratios hub / peer reported with ``--peer`` (below 1: the hub needs less)."""


def _dig(result: dict[str, Any], path: tuple[str, ...]) -> Any:
    value: Any = result
    for key in path:
        value = value[key]
    return value


def median_of_runs(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One result whose numbers are the medians over ``runs`` (same keys as one run)."""

    def merge(values: list[Any]) -> Any:
        first = values[0]
        if isinstance(first, dict):
            return {k: merge([v[k] for v in values]) for k in first}
        if isinstance(first, int | float) and not isinstance(first, bool):
            present = [v for v in values if v is not None]
            return round(statistics.median(present), 3) if present else None
        return first

    return merge(runs) if len(runs) > 1 else runs[0]


def compare(ours: dict[str, Any], peer: dict[str, Any]) -> dict[str, Any]:
    """The {"peer", "ratio", "agree"} part of the JSON: answers agree when both delivered
    every published message to every GUI (or superseded it under the overflow rule)."""
    ratio = {}
    for name, path in RATIO_KEYS.items():
        a, b = _dig(ours, path), _dig(peer, path)
        ratio[name] = round(a / b, 3) if a is not None and b else None
    return {"peer": peer, "ratio": ratio, "agree": ours["dropped"] == 0 == peer["dropped"]}


@click.command("hub")
@click.option("--robots", default=100, show_default=True, help="Simulated robots.")
@click.option("--rate", default=5.0, show_default=True, help="robot_state per robot per second.")
@click.option("--guis", default=5, show_default=True, help="GUI clients subscribed to all states.")
@click.option("--seconds", default=10.0, show_default=True, help="Measured duration.")
@click.option("--robot-procs", default=2, show_default=True, help="Processes for the robots.")
@click.option("--full-app", is_flag=True, help="Run every server component, not the hub alone.")
@click.option(
    "--peer", is_flag=True, help="Also run FastAPI's plain broadcast, interleaved with the hub."
)
@click.option(
    "--rounds",
    default=1,
    show_default=True,
    type=click.IntRange(min=1),
    help="Runs of each contender (medians reported; with --peer: hub, peer, hub, peer, ...).",
)
@click.option(
    "--slow-gui",
    "slow_gui_ms",
    default=0.0,
    show_default=True,
    type=click.FloatRange(min=0),
    help="Add one GUI that pauses this many ms after each frame it reads (0: none).",
)
@click.option("--servers", type=click.IntRange(min=1), help="Server processes on a broker.")
@click.option("--db", "db_url", help="With --servers: postgresql+asyncpg:// URL.")
@click.option("--broker", "broker_url", help="With --servers: redis:// URL.")
@click.option("--json", "as_json", is_flag=True, help="Print only the JSON line on stdout.")
def hub(
    robots: int,
    rate: float,
    guis: int,
    seconds: float,
    robot_procs: int,
    full_app: bool,
    peer: bool,
    rounds: int,
    slow_gui_ms: float,
    servers: int | None,
    db_url: str | None,
    broker_url: str | None,
    as_json: bool,
) -> None:
    """Hub throughput and publish-to-GUI latency over real WebSockets."""
    if robots < 1 or guis < 1 or rate <= 0 or seconds <= WARMUP_S:
        raise click.UsageError(f"need robots >= 1, guis >= 1, rate > 0, seconds > {WARMUP_S}")
    if servers is not None:  # several processes on a broker: bench/hub_cluster.py
        from .hub_cluster import cluster_command

        cluster_command(servers, db_url, broker_url, (robots, rate, guis, seconds, robot_procs))
        return
    args = (robots, rate, guis, seconds, robot_procs, full_app)
    ours: list[dict[str, Any]] = []
    theirs: list[dict[str, Any]] = []
    for _ in range(rounds):
        ours.append(run_benchmark(*args, slow_gui_ms=slow_gui_ms))
        if peer:
            theirs.append(run_benchmark(*args, peer=True, slow_gui_ms=slow_gui_ms))
    result = median_of_runs(ours)
    if rounds > 1:
        result["rounds"] = rounds
    if peer:
        result.update(compare(result, median_of_runs(theirs)))
    if not as_json:
        for who, r in [("hub", result), *([("peer", result["peer"])] if peer else [])]:
            click.echo(
                f"{who}: {robots} robots x {rate} Hz -> {guis} GUIs: in {r['msgs_in_per_s']}/s, "
                f"out {r['msgs_out_per_s']}/s in {r['frames_out_per_s']} frames/s, latency "
                f"{r['latency_ms']}, dropped {r['dropped']}, server CPU "
                f"{r['server_cpu_percent']}%"
            )
    print_result(result)


def _worker_main(argv: Sequence[str]) -> None:
    parser = argparse.ArgumentParser(prog="bench.hub")
    sub = parser.add_subparsers(dest="role", required=True)
    s = sub.add_parser("server")
    s.add_argument("--robots", type=int, required=True)
    s.add_argument("--full-app", action="store_true")
    s.add_argument("--peer", action="store_true")
    r = sub.add_parser("robots")
    r.add_argument("--url", required=True)
    r.add_argument("--first", type=int, required=True)
    r.add_argument("--count", type=int, required=True)
    r.add_argument("--rate", type=float, required=True)
    r.add_argument("--peer", action="store_true")
    g = sub.add_parser("guis")
    g.add_argument("--url", required=True)
    g.add_argument("--guis", type=int, required=True)
    g.add_argument("--admin-url", required=True)
    g.add_argument("--admin-token", required=True)
    g.add_argument("--slow-ms", type=float, default=0.0)
    g.add_argument("--peer", action="store_true")
    args = parser.parse_args(argv)
    try:
        import uvloop

        runner: Any = uvloop.run
    except ImportError:  # pragma: no cover - uvloop comes with uvicorn[standard]
        runner = asyncio.run
    if args.role == "server":
        runner(_serve(args.robots, args.full_app, args.peer))
    elif args.role == "robots":
        runner(_robots(args.url, args.first, args.count, args.rate, args.peer))
    else:
        runner(
            _guis(args.url, args.guis, args.admin_url, args.admin_token, args.peer, args.slow_ms)
        )


if __name__ == "__main__":
    _worker_main(sys.argv[1:])
