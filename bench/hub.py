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
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import click

from guidebot.benchutil import percentiles, print_result

GUI_TOKEN = "bench-gui-token"
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
async def _serve(robots: int, full_app: bool) -> None:
    """Server process: print the bound port, then serve until killed."""
    import backend.app
    from backend.auth import Role
    from backend.settings import Settings, StaticToken
    from backend.testing import running_server

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
    async with running_server(settings) as server:
        if os.environ.get("BENCH_NO_GC_FREEZE"):  # measure the hub without its GC policy
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


async def _robots(url: str, first: int, count: int, rate: float) -> None:
    """Robot process: connect ``count`` robots, wait for the start time, publish, report."""
    from guidebot.client import HubClient

    clients = [
        HubClient(url, robot_token(i), heartbeat_interval=5.0, connect_timeout=60.0)
        for i in range(first, first + count)
    ]
    for start in range(0, count, 50):  # connect in waves: the accept queue is finite
        await asyncio.gather(*(c.start() for c in clients[start : start + 50]))
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

    async def run(k: int, client: HubClient) -> None:
        next_at = start_at + period * k / count
        seq = 0
        name = client.name
        while next_at < end_at:
            delay = next_at - time.time()
            if delay > 0:
                await asyncio.sleep(delay)
            seq += 1
            client.publish(
                "robot_state",
                {"robot": name, "x": 1.0, "y": 2.0, "theta": 0.5, "battery": 0.8, "seq": seq},
            )
            next_at += period
        published[k] = seq

    await asyncio.gather(*(run(k, c) for k, c in enumerate(clients)))
    cpu_percent = 100 * (time.process_time() - cpu0) / (time.monotonic() - t0)
    health = probe.report()
    await asyncio.gather(*(c.sync(timeout=30.0) for c in clients))
    Probe.full_collection(health)
    dropped_here = sum(c.dropped for c in clients)
    for c in clients:
        await c.close(flush=False)
    result = {
        "published": sum(published),
        "client_dropped": dropped_here,
        "cpu": cpu_percent,
        **health,
    }
    print(json.dumps(result), flush=True)


async def _guis(url: str, guis: int, admin_url: str, admin_token: str) -> None:
    """GUI process: subscribe to robot_state, measure latency and gaps per robot."""
    import httpx

    from guidebot.client import HubClient
    from guidebot.messages import Message

    clients = [HubClient(url, GUI_TOKEN, heartbeat_interval=5.0) for _ in range(guis)]
    for c in clients:
        await c.start()
    # array, not list: a list of 500 000 floats would make every full GC of this process slow.
    latencies = array.array("d")
    received = [0] * guis
    last_seq: list[dict[str, int]] = [{} for _ in range(guis)]
    gaps = [0] * guis
    window = [0.0, 0.0]
    slow: dict[int, float] = {}  # second of the window -> worst latency over 100 ms in it

    def handler_for(g: int) -> Any:
        seqs = last_seq[g]

        def handle(message: Message) -> None:
            now = time.time()
            received[g] += 1
            payload = message.payload
            robot, seq = payload["robot"], payload["seq"]
            previous = seqs.get(robot, 0)
            if seq > previous + 1:
                gaps[g] += seq - previous - 1
            seqs[robot] = seq
            if window[0] <= message.timestamp <= window[1]:
                latency = now - message.timestamp
                latencies.append(latency)
                if latency > 0.1:
                    second = int(message.timestamp - window[0])
                    slow[second] = max(slow.get(second, 0.0), latency)

        return handle

    for g, c in enumerate(clients):
        c.subscribe("robot_state", handler_for(g))
    await asyncio.gather(*(c.sync() for c in clients))
    probe = Probe()
    probe.start(freeze=True)
    print("READY", flush=True)
    start_at = await _read_start_time()
    seconds = await _read_start_time()
    window[0], window[1] = start_at + WARMUP_S, start_at + seconds
    await asyncio.sleep(max(0.0, window[0] - time.time()))
    probe.reset()
    cpu0, t0 = time.process_time(), time.monotonic()
    await asyncio.sleep(max(0.0, window[1] - time.time()))
    cpu_percent = 100 * (time.process_time() - cpu0) / (time.monotonic() - t0)
    health = probe.report()
    done = await _read_start_time()  # the robots finished and synced: everything was routed
    del done
    await asyncio.gather(*(c.sync(timeout=30.0) for c in clients))
    async with httpx.AsyncClient() as http:
        stats = (
            await http.get(f"{admin_url}/api/hub/clients", params={"token": admin_token})
        ).json()
    superseded = sum(c["superseded"] for c in stats["clients"] if c["name"].startswith("gui"))
    for c in clients:
        await c.close(flush=False)
    Probe.full_collection(health)
    in_window = len(latencies)
    print(
        json.dumps(
            {
                "received": sum(received),
                "gaps": sum(gaps),
                "superseded": superseded,
                "latency_ms": percentiles([x * 1000 for x in latencies]),
                "latency_samples": in_window,
                "cpu_percent": round(cpu_percent, 1),
                "slow_seconds": {k: round(v * 1000) for k, v in sorted(slow.items())},
                **health,
            }
        ),
        flush=True,
    )


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
    robots: int, rate: float, guis: int, seconds: float, robot_procs: int, full_app: bool
) -> dict[str, Any]:
    import psutil

    server = _spawn(["server", "--robots", str(robots)] + (["--full-app"] if full_app else []))
    workers: list[subprocess.Popen[str]] = []
    try:
        port = int(_expect(server, "PORT").split()[1])
        url = f"ws://127.0.0.1:{port}/ws"
        _log(f"server pid {server.pid} on port {port}")
        from backend.settings import DEFAULT_ADMIN_TOKEN

        gui_proc = _spawn(
            [
                "guis",
                *("--url", url, "--guis", str(guis)),
                *("--admin-url", f"http://127.0.0.1:{port}", "--admin-token", DEFAULT_ADMIN_TOKEN),
            ]
        )
        workers.append(gui_proc)
        _expect(gui_proc, "READY")
        procs = max(1, min(robot_procs, robots))
        robot_workers = []
        for p in range(procs):
            first = robots * p // procs
            count = robots * (p + 1) // procs - first
            proc = _spawn(
                [
                    "robots",
                    *("--url", url, "--first", str(first)),
                    *("--count", str(count), "--rate", str(rate)),
                ]
            )
            robot_workers.append(proc)
            workers.append(proc)
        for proc in robot_workers:
            _expect(proc, "READY")
        _log(f"{robots} robots and {guis} GUIs connected; running {seconds} s")
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
    _log(
        f"published {published}, GUI receipts {gui_result['received']} of {expected}, "
        f"superseded {gui_result['superseded']}, seq gaps {gui_result['gaps']}, "
        f"client-side dropped {sum(r['client_dropped'] for r in robot_results)}, "
        f"latency samples {gui_result['latency_samples']}; CPU % GUI process "
        f"{gui_result['cpu_percent']}, robot processes {[round(r['cpu']) for r in robot_results]}"
    )
    if gui_result["slow_seconds"]:
        _log(f"seconds with latency over 100 ms (worst ms): {gui_result['slow_seconds']}")
    for who, health in [
        ("server", server_health),
        ("guis", gui_result),
        *((f"robots{k}", r) for k, r in enumerate(robot_results)),
    ]:
        _log(f"{who}: loop lag ms {health['lag_ms']}, gc {health['gc']}")
    return {
        "robots": robots,
        "rate_hz": rate,
        "guis": guis,
        "msgs_in_per_s": round(published / seconds, 1),
        "msgs_out_per_s": round(gui_result["received"] / seconds, 1),
        "latency_ms": gui_result["latency_ms"],
        "dropped": dropped,
        "server_cpu_percent": round(100.0 * busy / elapsed, 1),
    }


@click.command("hub")
@click.option("--robots", default=100, show_default=True, help="Simulated robots.")
@click.option("--rate", default=5.0, show_default=True, help="robot_state per robot per second.")
@click.option("--guis", default=5, show_default=True, help="GUI clients subscribed to all states.")
@click.option("--seconds", default=10.0, show_default=True, help="Measured duration.")
@click.option("--robot-procs", default=2, show_default=True, help="Processes for the robots.")
@click.option("--full-app", is_flag=True, help="Run every server component, not the hub alone.")
@click.option("--json", "as_json", is_flag=True, help="Print only the JSON line on stdout.")
def hub(
    robots: int,
    rate: float,
    guis: int,
    seconds: float,
    robot_procs: int,
    full_app: bool,
    as_json: bool,
) -> None:
    """Hub throughput and publish-to-GUI latency over real WebSockets."""
    if robots < 1 or guis < 1 or rate <= 0 or seconds <= WARMUP_S:
        raise click.UsageError(f"need robots >= 1, guis >= 1, rate > 0, seconds > {WARMUP_S}")
    result = run_benchmark(robots, rate, guis, seconds, robot_procs, full_app)
    if not as_json:
        click.echo(
            f"{robots} robots x {rate} Hz -> {guis} GUIs: in {result['msgs_in_per_s']}/s, "
            f"out {result['msgs_out_per_s']}/s, latency {result['latency_ms']}, "
            f"dropped {result['dropped']}, server CPU {result['server_cpu_percent']}%"
        )
    print_result(result)


def _worker_main(argv: Sequence[str]) -> None:
    parser = argparse.ArgumentParser(prog="bench.hub")
    sub = parser.add_subparsers(dest="role", required=True)
    s = sub.add_parser("server")
    s.add_argument("--robots", type=int, required=True)
    s.add_argument("--full-app", action="store_true")
    r = sub.add_parser("robots")
    r.add_argument("--url", required=True)
    r.add_argument("--first", type=int, required=True)
    r.add_argument("--count", type=int, required=True)
    r.add_argument("--rate", type=float, required=True)
    g = sub.add_parser("guis")
    g.add_argument("--url", required=True)
    g.add_argument("--guis", type=int, required=True)
    g.add_argument("--admin-url", required=True)
    g.add_argument("--admin-token", required=True)
    args = parser.parse_args(argv)
    try:
        import uvloop

        runner: Any = uvloop.run
    except ImportError:  # pragma: no cover - uvloop comes with uvicorn[standard]
        runner = asyncio.run
    if args.role == "server":
        runner(_serve(args.robots, args.full_app))
    elif args.role == "robots":
        runner(_robots(args.url, args.first, args.count, args.rate))
    else:
        runner(_guis(args.url, args.guis, args.admin_url, args.admin_token))


if __name__ == "__main__":
    _worker_main(sys.argv[1:])
