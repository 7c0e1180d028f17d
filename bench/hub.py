"""Benchmark of the hub: N robots publish robot_state at HZ, M GUIs subscribe to all of it.

``guidebot bench hub --robots 1000 --rate 5 --guis 5 --seconds 15 --json``

Every party is a real process speaking the real WebSocket protocol:
- the server (``create_app`` on 127.0.0.1, port 0, hub only unless ``--full-app``) runs in its
  own process so its CPU can be read with psutil;
- the robots are split over ``--robot-procs`` processes; each robot publishes robot_state with a
  sequence number at ``rate`` Hz, phases spread evenly, as HubClient frames it;
- the GUIs share one process and subscribe to ``robot_state``.

Robots and GUIs connect with picows (the ``bench`` extra), a WebSocket client written in Cython:
a real robot spends its own computer on its one link, but here hundreds of links share the
machine with the server they measure, and with the ``websockets`` client the bench's processes
took as much CPU as the server (GUI process 41 %, robot processes 2 x 18 %; with picows 27 % and
2 x 11 %). The slow GUI of ``--slow-gui`` reads with ``websockets``, one frame at a time.

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

The last line printed is one JSON object with the keys of issue 2. This module runs the
benchmark; the worker processes are in bench/hub_workers.py, the peers (``--peer``, with
``--peer-server fastapi`` or ``picows``) in bench/hub_peer.py.
"""

from __future__ import annotations

import contextlib
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import click

from guidebot.benchutil import print_result

from .hub_workers import GUI_TOKEN as GUI_TOKEN
from .hub_workers import HUB_LISTENERS, PEER_SERVERS, WARMUP_S, _log
from .hub_workers import _open_gui as _open_gui
from .hub_workers import robot_name as robot_name
from .hub_workers import robot_token as robot_token


# -- orchestration -------------------------------------------------------------------------------
def _spawn(args: Sequence[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "bench.hub_workers", *args],
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
    peer: str | None = None,
    slow_gui_ms: float = 0.0,
    listener: str = "picows",
) -> dict[str, Any]:
    """One run against the hub (its clients on the ``listener`` of HUB_LISTENERS), or against
    the ``peer`` broadcast named (PEER_SERVERS)."""
    import psutil

    who = "peer" if peer else "hub"
    flags = (["--full-app"] if full_app else []) + (["--peer", peer] if peer else [])
    flags += [] if peer else ["--listener", listener]
    server = _spawn(["server", "--robots", str(robots), *flags])
    workers: list[subprocess.Popen[str]] = []
    try:
        _, port, hub_port = _expect(server, "PORT").split()
        url = f"ws://127.0.0.1:{hub_port}/ws"
        _log(f"{who}: server pid {server.pid} on port {port}, hub clients on {url}")
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
            for pipe in (proc.stdin, proc.stdout):
                if pipe is not None:
                    pipe.close()
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
        **({} if peer else {"listener": listener}),
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
@click.option("--peer", is_flag=True, help="Also run a plain broadcast, interleaved with the hub.")
@click.option(
    "--peer-server",
    type=click.Choice(PEER_SERVERS),
    default="fastapi",
    show_default=True,
    help="The broadcast --peer runs: FastAPI's tutorial, or a picows (Cython) server.",
)
@click.option(
    "--listener",
    type=click.Choice(HUB_LISTENERS),
    default="picows",
    show_default=True,
    help="Where the hub's clients connect: its own listener (hub_ws_port), or /ws via uvicorn.",
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
    peer_server: str,
    listener: str,
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
        ours.append(run_benchmark(*args, slow_gui_ms=slow_gui_ms, listener=listener))
        if peer:
            theirs.append(run_benchmark(*args, peer=peer_server, slow_gui_ms=slow_gui_ms))
    result = median_of_runs(ours)
    if rounds > 1:
        result["rounds"] = rounds
    if peer:
        result.update(compare(result, {"server": peer_server, **median_of_runs(theirs)}))
    if not as_json:
        for who, r in [("hub", result), *([("peer", result["peer"])] if peer else [])]:
            click.echo(
                f"{who}: {robots} robots x {rate} Hz -> {guis} GUIs: in {r['msgs_in_per_s']}/s, "
                f"out {r['msgs_out_per_s']}/s in {r['frames_out_per_s']} frames/s, latency "
                f"{r['latency_ms']}, dropped {r['dropped']}, server CPU "
                f"{r['server_cpu_percent']}%"
            )
    print_result(result)
