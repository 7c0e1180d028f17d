"""`guidebot bench hub --servers N`: the hub benchmark over N server processes and a broker.

``guidebot bench hub --servers 2 --db postgresql+asyncpg://... --broker redis://... --json``

N `guidebot server --broker` processes (bench/servers.py; the first one leads) share one
PostgreSQL database and one Redis. The robots are the hub benchmark's robot processes
(bench/hub.py), at least one per server: robot process p connects to server p mod N. The GUIs
are spread the same way (GUI g on server g mod N) and run in one process of this module, which
splits each robot_state's latency (publish timestamp to receipt) by whether the robot is on the
GUI's own server ("local") or on another one ("cross": through Redis).

The JSON has the hub benchmark's keys where they apply, plus "servers", "latency_ms" (all
receipts), "local_latency_ms" and "cross_process_latency_ms", "server_cpu_percent" (the sum over
the servers) and "server_cpu_percent_each". "dropped" counts states a GUI never received (no
superseded states are subtracted: the servers' /api/hub/clients is not queried).
"""

from __future__ import annotations

import argparse
import array
import asyncio
import contextlib
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import orjson

from guidebot.benchutil import percentiles, print_result

from .hub import GUI_TOKEN, _expect, _open_gui, _spawn, _tell, robot_name, robot_token
from .hub_workers import WARMUP_S
from .servers import start_servers

__all__ = ["cluster_command", "run_cluster"]


def _server_of_robot(robots: int, procs: int, servers: int) -> list[int]:
    """For each robot index, the server its process connects to (as run_cluster spreads them)."""
    where = []
    for p in range(procs):
        count = robots * (p + 1) // procs - robots * p // procs
        where += [p % servers] * count
    return where


async def _cluster_guis(urls: list[str], guis: int, robot_server: list[int]) -> None:
    """GUI process: ``guis`` GUIs spread over ``urls``; latency split local / cross-process."""
    window = [0.0, 0.0]
    local: array.array[float] = array.array("d")
    cross: array.array[float] = array.array("d")
    server_of = {robot_name(i): s for i, s in enumerate(robot_server)}
    received = [0]

    async def read(ws: Any, home: int) -> None:
        with contextlib.suppress(Exception):
            async for frame in ws:
                now = time.time()
                data = orjson.loads(frame)
                for message in data if isinstance(data, list) else (data,):
                    if message.get("type") != "robot_state":
                        continue
                    received[0] += 1
                    stamp = message["timestamp"]
                    if window[0] <= stamp <= window[1]:
                        same = server_of.get(message["payload"]["robot"]) == home
                        (local if same else cross).append(now - stamp)

    homes = [g % len(urls) for g in range(guis)]
    sockets = [await _open_gui(urls[h], False, GUI_TOKEN) for h in homes]
    tasks = [asyncio.create_task(read(ws, h)) for ws, h in zip(sockets, homes, strict=True)]
    print("READY", flush=True)
    loop = asyncio.get_running_loop()
    start_at = float(await loop.run_in_executor(None, sys.stdin.readline))
    seconds = float(await loop.run_in_executor(None, sys.stdin.readline))
    window[0], window[1] = start_at + WARMUP_S, start_at + seconds
    await loop.run_in_executor(None, sys.stdin.readline)  # the robots are done
    await asyncio.sleep(2.0)  # what is still on its way through the broker
    for ws in sockets:
        await ws.close()
    for task in tasks:
        task.cancel()
    result = {
        "received": received[0],
        "latency_ms": percentiles([x * 1000 for x in (*local, *cross)]),
        "local_latency_ms": percentiles([x * 1000 for x in local]),
        "cross_process_latency_ms": percentiles([x * 1000 for x in cross]),
        "samples": {"local": len(local), "cross": len(cross)},
    }
    print(json.dumps(result), flush=True)


async def run_cluster(
    servers: int,
    robots: int,
    rate: float,
    guis: int,
    seconds: float,
    robot_procs: int,
    db_url: str,
    broker_url: str,
) -> dict[str, Any]:
    """One run of the hub benchmark over ``servers`` processes (see the module's docstring)."""
    import psutil

    procs = max(robot_procs, servers)
    tokens = [
        {"token": robot_token(i), "name": robot_name(i), "role": "robot"} for i in range(robots)
    ]
    tokens.append({"token": GUI_TOKEN, "name": "benchgui", "role": "gui"})
    names = [f"s{k}" for k in range(servers)]
    with tempfile.TemporaryDirectory(prefix="guidebot-hub-cluster-") as root:
        async with start_servers(names, db_url, broker_url, Path(root), tokens) as running:
            urls = [f"ws://127.0.0.1:{s.port}/ws" for s in running]
            where = _server_of_robot(robots, procs, servers)
            workers = []
            try:
                gui_args = ["guis", "--guis", str(guis), "--where", ",".join(map(str, where))]
                gui_proc = _spawn_cluster([*gui_args, *(a for u in urls for a in ("--url", u))])
                workers.append(gui_proc)
                _expect(gui_proc, "READY")
                robot_workers = []
                for p in range(procs):
                    first = robots * p // procs
                    count = robots * (p + 1) // procs - first
                    args = ["robots", "--url", urls[p % servers], "--first", str(first)]
                    robot_workers.append(
                        _spawn([*args, "--count", str(count), "--rate", str(rate)])
                    )
                workers += robot_workers
                for proc in robot_workers:
                    _expect(proc, "READY")
                start_at = time.time() + 0.5
                _tell([gui_proc, *robot_workers], start_at)
                _tell([gui_proc, *robot_workers], seconds)
                ps = [psutil.Process(s.process.pid) for s in running]
                await asyncio.sleep(max(0.0, start_at + WARMUP_S - time.time()))
                before = [p.cpu_times() for p in ps]
                t0 = time.monotonic()
                await asyncio.sleep(max(0.0, start_at + seconds - time.time()))
                after = [p.cpu_times() for p in ps]
                elapsed = time.monotonic() - t0
                robot_results = [json.loads(_expect(p, "{")) for p in robot_workers]
                _tell([gui_proc], 0)
                gui_result = json.loads(_expect(gui_proc, "{"))
            finally:
                for proc in workers:
                    with contextlib.suppress(ProcessLookupError):
                        proc.kill()
                    proc.wait()
                    for pipe in (proc.stdin, proc.stdout):
                        if pipe is not None:
                            pipe.close()
    cpu = [
        round(100 * (a.user - b.user + a.system - b.system) / elapsed, 1)
        for a, b in zip(after, before, strict=True)
    ]
    published = sum(r["published"] for r in robot_results)
    return {
        "servers": servers,
        "robots": robots,
        "rate_hz": rate,
        "guis": guis,
        "msgs_in_per_s": round(published / seconds, 1),
        "msgs_out_per_s": round(gui_result["received"] / seconds, 1),
        "latency_ms": gui_result["latency_ms"],
        "local_latency_ms": gui_result["local_latency_ms"],
        "cross_process_latency_ms": gui_result["cross_process_latency_ms"],
        "latency_samples": gui_result["samples"],
        "dropped": max(0, published * guis - gui_result["received"]),
        "refused": sum(r["errors"] for r in robot_results),
        "server_cpu_percent": round(sum(cpu), 1),
        "server_cpu_percent_each": cpu,
    }


def cluster_command(
    servers: int,
    db_url: str | None,
    broker_url: str | None,
    load: tuple[int, float, int, float, int],
) -> None:
    """`guidebot bench hub --servers N`: check the options, run once, print the JSON line."""
    import click

    if not db_url or not broker_url:
        raise click.UsageError("--servers needs --db (postgresql+asyncpg://...) and --broker")
    robots, rate, guis, seconds, robot_procs = load
    result = asyncio.run(
        run_cluster(servers, robots, rate, guis, seconds, robot_procs, db_url, broker_url)
    )
    print_result(result)


def _spawn_cluster(args: list[str]) -> Any:
    import subprocess

    return subprocess.Popen(
        [sys.executable, "-m", "bench.hub_cluster", *args],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        bufsize=1,
    )


def _worker_main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(prog="bench.hub_cluster")
    sub = parser.add_subparsers(dest="role", required=True)
    g = sub.add_parser("guis")
    g.add_argument("--url", action="append", required=True)
    g.add_argument("--guis", type=int, required=True)
    g.add_argument("--where", required=True, help="the server of each robot, comma-separated")
    args = parser.parse_args(argv)
    where = [int(w) for w in args.where.split(",")]
    asyncio.run(_cluster_guis(args.url, args.guis, where))


if __name__ == "__main__":
    _worker_main(sys.argv[1:])
