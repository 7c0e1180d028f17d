"""Traffic Manager benchmark: path queries on a large site and area-lock round trips over the
hub while many robots ask at once.

    guidebot bench traffic --nodes 10000 --robots 1000 --json

Last line: {"destination_lookup_ms", "any_pair_path_ms", "any_pair_path_cpu_ms", "build_s",
"build_workers_s", "lock_rtt_ms", "idle_max_stall_ms", "publish_max_stall_ms",
"load_max_stall_ms", "stalls", "rollout_ms", and with ``--peer`` "peer", "ratio", "agree"}.
destination_lookup_ms: a robot's position (any node) to a site destination (point of interest,
charging station, wait point), the queries robots make: a walk down a distance field
precomputed when the site is built (a table lookup, not a search). any_pair_path_ms: between
two random nodes, the elevator transit read or the search of one floor (SciPy's Dijkstra,
guidebot/site/floor_paths.py), in wall and in CPU time (the CPU figure is what a preempting
neighbour process does not change).
build_s: SiteGraph construction (landmarks, elevator stops' distances, the destinations'
distance fields) in this process; build_workers_s: the same as the server builds it, the tables
in two worker processes (backend/site/graph_build.py). With ``--peer``, networkx (building its
DiGraph, bidirectional Dijkstra per query) runs the same queries interleaved with ours, and
the path lengths must agree. lock_rtt_ms: request_area sent by a robot
endpoint of the JCentral hub of a running server until its area_granted arrives (the
``--ws-robots`` WebSocket robots are printed apart), all robots asking concurrently,
each for its own area (no waiting behind another robot: the round trip itself), each robot
asking at random times at ``--rate`` per second (open loop). The closed-loop saturation rate
(every robot asking again the moment it is answered) is printed as information.
*_max_stall_ms: the longest event-loop stall (a 1 ms ticker's lateness) of that running server
while it takes the site again by PUT /api/site (publish) and by POST /api/site/import (load,
YAML), each until ``--followers`` robots in another process have the new version, and while
idle as long as the longer of the two; "stalls" gives per window also the 99.9th percentile of
the ticks' lateness and the ticks more than 20 ms late. rollout_ms: per reload, publish to the
last follower's site_loaded.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import random
import sys
import tempfile
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import click
import httpx
import orjson

from backend.hub import Hub
from backend.settings import Settings
from backend.site.graph_build import build_site_graph
from backend.testing import RunningServer, running_server
from backend.traffic.manager import TrafficManager
from building_sim.simulator import BuildingSimulator
from guidebot.benchutil import LoopStall, percentiles, print_result
from guidebot.client import HubClient
from guidebot.site.building_config import load_building
from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site
from guidebot.site.synthetic import synthetic_site
from guidebot.site.validate import validate_site
from guidebot.site.yamlio import dump_site

__all__ = ["main"]

ROLLOUT_TIMEOUT_S = 120.0
"""How long a reload window waits for the following robots to confirm the new site."""


def bench_paths(graph: SiteGraph, nodes: list[str], goals: list[str], queries: int) -> list[float]:
    rng = random.Random(7)
    samples = []
    for _ in range(queries):
        start, goal = rng.choice(nodes), rng.choice(goals)
        t0 = time.perf_counter()
        graph.shortest_path(start, goal)
        samples.append((time.perf_counter() - t0) * 1000)
    return samples


def bench_any_pair(
    graph: SiteGraph, nodes: list[str], queries: int
) -> tuple[list[float], list[float]]:
    """Wall and CPU milliseconds per query: on a shared machine a query preempted by another
    process shows in the wall time only."""
    rng = random.Random(8)
    samples, cpu = [], []
    for _ in range(queries):
        start, goal = rng.sample(nodes, 2)
        c0, t0 = time.thread_time(), time.perf_counter()
        graph.shortest_path(start, goal)
        samples.append((time.perf_counter() - t0) * 1000)
        cpu.append((time.thread_time() - c0) * 1000)
    return samples, cpu


def peer_graph(graph: SiteGraph) -> tuple[Any, float]:
    """The same weighted directed graph in networkx, and the seconds it took to build."""
    import networkx as nx

    t0 = time.perf_counter()
    g = nx.DiGraph()
    g.add_nodes_from(graph.names)
    g.add_weighted_edges_from((a, b, c) for a, out in graph.adj.items() for b, c in out)
    return g, time.perf_counter() - t0


def bench_peer(
    graph: SiteGraph, peer: Any, pairs: list[tuple[str, str]]
) -> tuple[list[float], list[float], int]:
    """Each pair with both, alternating which goes first; returns (ours ms, networkx ms,
    pairs whose lengths differ by more than 1e-9 relative)."""
    import networkx as nx

    ours, theirs, disagree = [], [], 0
    for k, (start, goal) in enumerate(pairs):
        for turn in (0, 1) if k % 2 == 0 else (1, 0):
            t0 = time.perf_counter()
            if turn == 0:
                mine = graph.shortest_path(start, goal).length_m
                ours.append((time.perf_counter() - t0) * 1000)
            else:
                length, _ = nx.bidirectional_dijkstra(peer, start, goal)
                theirs.append((time.perf_counter() - t0) * 1000)
        if abs(mine - length) > 1e-9 * max(1.0, length):
            disagree += 1
    return ours, theirs, disagree


Reload = tuple[dict[str, dict[str, float]], dict[str, float | None]]
"""Per reload window its loop stalls, and per reload its rollout's ms (``bench_reload``)."""


async def bench_reload(server: RunningServer, site: Site, followers: int) -> Reload:
    """Event-loop stalls while the running server takes the site again by PUT /api/site (JSON,
    a node moved) and POST /api/site/import (YAML), then over an idle window as long as the
    longer of the two (the machine's own noise over the same time): per window the longest
    stall ("max"), the 99.9th percentile of the ticks' lateness ("p999") and the ticks more
    than 20 ms late ("over_20"). The first ``followers`` robots follow the site from another
    process (bench/site_followers.py): a reload window lasts until every one of them has
    confirmed the new version, and the rollout's time (publish to the last site_loaded, ms)
    is returned per window. The bodies are encoded before the probe starts (the client's
    work is not the server's), and the client makes one request before (its first imports
    anyio's backend, 20-30 ms on the loop); the client shares the server's loop, as a robot's
    would."""
    doc = site.model_dump(mode="json")
    doc["nodes"][0]["x"] += 0.5
    body = orjson.dumps(doc)
    yaml_text = dump_site(site).encode()
    headers = {"Authorization": f"Bearer {server.admin_token}"}
    probes: dict[str, LoopStall] = {}
    rollout: dict[str, float | None] = {}
    robots = [(r.name, r.token) for r in site.robots[:followers]]
    async with (
        httpx.AsyncClient(base_url=server.url, headers=headers, timeout=300) as http,
        site_followers(server.ws_url, robots),
    ):
        (await http.get("/api/health")).raise_for_status()
        async with LoopStall() as probes["publish"]:
            reply = await http.put(
                "/api/site", content=body, headers={"Content-Type": "application/json"}
            )
            reply.raise_for_status()
            rollout["publish"] = await _rolled_out(http, reply.json()["version"], len(robots))
        async with LoopStall() as probes["load"]:
            reply = await http.post(
                "/api/site/import",
                content=yaml_text,
                headers={"Content-Type": "application/yaml"},
            )
            reply.raise_for_status()
            rollout["load"] = await _rolled_out(http, reply.json()["version"], len(robots))
        async with LoopStall() as probes["idle"]:
            await asyncio.sleep(max(probes["publish"].seconds, probes["load"].seconds))
    stalls = {
        name: {
            "max": round(probe.max_ms, 2),
            "p999": round(probe.percentile(0.999), 2),
            "over_20": probe.over(20.0),
            "seconds": round(probe.seconds, 2),
        }
        for name, probe in probes.items()
    }
    return stalls, rollout


@contextlib.asynccontextmanager
async def site_followers(url: str, robots: list[tuple[str, str]]) -> AsyncIterator[None]:
    """``robots`` (name, token) following the site from a process of their own, connected
    (welcomed) when the block starts; the process ends with the block."""
    if not robots:
        yield
        return
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "bench.site_followers",
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
    )
    assert process.stdin is not None and process.stdout is not None
    try:
        process.stdin.write(orjson.dumps({"url": url, "robots": robots}) + b"\n")
        await process.stdin.drain()
        line = await asyncio.wait_for(process.stdout.readline(), 120)
        if line.strip() != b"ready":
            code = await asyncio.wait_for(process.wait(), 30)
            raise RuntimeError(
                f"site followers did not start (exit status {code}; why: on standard error)"
            )
        yield
    finally:
        process.stdin.close()
        try:
            await asyncio.wait_for(process.wait(), 30)
        except TimeoutError:
            process.kill()
            await process.wait()


async def _rolled_out(http: httpx.AsyncClient, version: int, robots: int) -> float | None:
    """Wait until ``robots`` robots have confirmed ``version``: the rollout's ms (None when
    no robot follows the site; RuntimeError after ``ROLLOUT_TIMEOUT_S``)."""
    if robots == 0:
        return None
    deadline = time.monotonic() + ROLLOUT_TIMEOUT_S
    status: dict[str, Any] = {}
    while time.monotonic() < deadline:
        status = (await http.get("/api/site/rollout")).raise_for_status().json()
        if status["version"] == version and status["complete"]:
            if len(status["expected"]) != robots:
                raise RuntimeError(f"rollout expected {status['expected']}, not {robots} robots")
            return float(status["ms"])
        await asyncio.sleep(0.02)
    raise RuntimeError(f"version {version} not confirmed by {robots} robots: {status}")


async def bench_locks(
    site: Site, robots: int, rate: float, seconds: float, ws_robots: int, followers: int, tmp: Path
) -> tuple[list[float], list[float], int, Reload]:
    """Open loop: each robot asks at random times (Poisson, ``rate`` per second), as robots
    reaching restricted areas do. The first ``ws_robots`` robots are real WebSocket clients
    of a real server (uvicorn on 127.0.0.1); the others are in-process hub endpoints of that
    same server. Returns (in-process round trips, WebSocket round trips, requests made),
    measured after a 1 s warm-up, and the reloads (``bench_reload``, ``followers`` robots
    following the site). The site's elevator modules run on a Modbus simulator, so that the
    server polls its building as a deployed one does."""
    doc = site.model_dump(mode="json")
    async with BuildingSimulator(load_building(doc), port_zero=True) as building:
        for module in doc["modules"]:
            module["port"] = building.ports[module["id"]]
        site = validate_site(doc)
        site_file = tmp / "site.yaml"
        site_file.write_text(dump_site(site))
        settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp / 'bench.db'}", site=site_file)
        async with running_server(settings, start_timeout=300) as server:
            locks = await _ask_for_locks(server, site, robots, rate, seconds, ws_robots)
            return (*locks, await bench_reload(server, site, followers))


async def _ask_for_locks(
    server: RunningServer, site: Site, robots: int, rate: float, seconds: float, ws_robots: int
) -> tuple[list[float], list[float], int]:
    """The robots' requests against the running ``server`` (``bench_locks``)."""
    hub_samples: list[float] = []
    ws_samples: list[float] = []
    asked = 0
    hub = server.app.state.hub
    areas = server.app.state.traffic.locks.areas
    loop = asyncio.get_running_loop()
    clients = [
        HubClient(server.ws_url, site.robots[k].token) for k in range(min(ws_robots, robots))
    ]
    for client in clients:
        await client.start()
    for client in clients:
        await asyncio.wait_for(client.connected.wait(), 30)
    start = loop.time()
    warm_until, stop_at = start + 1.0, start + 1.0 + seconds

    async def robot(k: int) -> None:
        nonlocal asked
        rng = random.Random(k)
        name = site.robots[k].name
        endpoint = clients[k] if k < len(clients) else hub.endpoint(name)
        samples = ws_samples if k < len(clients) else hub_samples
        area = areas[k % len(areas)]
        while True:
            await asyncio.sleep(rng.expovariate(rate))
            if loop.time() >= stop_at:
                return
            t0 = time.perf_counter()
            reply = await endpoint.request(
                "request_area", {"robot": name, "area": area}, timeout=30.0
            )
            rtt = (time.perf_counter() - t0) * 1000
            if reply.type != "area_granted":
                raise RuntimeError(f"refused: {reply.payload}")
            endpoint.publish("release_area", {"robot": name, "area": area})
            asked += 1
            if loop.time() >= warm_until:
                samples.append(rtt)

    try:
        await asyncio.gather(*(robot(k) for k in range(robots)))
    finally:
        for client in clients:
            await client.close()
    return hub_samples, ws_samples, asked


async def saturation(site: Site, robots: int, rounds: int = 3) -> float:
    """Closed loop, every robot asking again at once: round trips per second at saturation."""
    hub = Hub()
    traffic = TrafficManager(hub.endpoint("traffic_manager"), site)
    await traffic.start()
    areas = traffic.locks.areas

    async def robot(k: int) -> None:
        name = f"S{k}"
        endpoint = hub.endpoint(name)
        for _ in range(rounds):
            await endpoint.request("request_area", {"robot": name, "area": areas[k % len(areas)]})
            endpoint.publish("release_area", {"robot": name, "area": areas[k % len(areas)]})

    t0 = time.perf_counter()
    await asyncio.gather(*(robot(k) for k in range(robots)))
    elapsed = time.perf_counter() - t0
    await traffic.stop()
    hub.close()
    return robots * rounds / elapsed


@click.command()
@click.option("--nodes", default=10_000, show_default=True, help="Nodes of the synthetic site.")
@click.option("--robots", default=1000, show_default=True, help="Robots asking for areas.")
@click.option("--queries", default=5000, show_default=True, help="Path queries to time.")
@click.option("--rate", default=1.0, show_default=True, help="Area requests per robot per s.")
@click.option("--seconds", default=5.0, show_default=True, help="Measured lock phase.")
@click.option(
    "--ws-robots", default=20, show_default=True, help="Robots that are WebSocket clients."
)
@click.option(
    "--followers",
    default=20,
    show_default=True,
    help="Robots (at most --robots) following the site from another process in the reloads.",
)
@click.option("--destinations", default=200, show_default=True, help="Points of interest.")
@click.option("--peer", is_flag=True, help="Also run networkx on the same queries, interleaved.")
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line on stdout.")
def main(
    nodes: int,
    robots: int,
    queries: int,
    rate: float,
    seconds: float,
    ws_robots: int,
    followers: int,
    destinations: int,
    peer: bool,
    as_json: bool,
) -> None:
    """Path and lock latency of the Traffic Manager."""
    if nodes < 4 or robots < 1 or queries < 1 or rate <= 0 or seconds <= 0:
        raise click.UsageError("need nodes >= 4, robots and queries >= 1, rate and seconds > 0")
    if followers < 0:
        raise click.UsageError("--followers is 0 or more")
    followers = min(followers, robots)
    if peer:
        try:
            import networkx  # noqa: F401
        except ImportError:
            raise click.UsageError("--peer needs networkx: pip install -e '.[peers]'") from None
    site = synthetic_site(nodes=nodes, robots=robots, areas=robots, pois=destinations)
    t0 = time.perf_counter()
    graph = SiteGraph(site)
    warm_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    asyncio.run(build_site_graph(site, 2, min_nodes=0))
    workers_s = time.perf_counter() - t0
    gc.collect()
    gc.freeze()  # the site is long-lived: keep the collector from rescanning it (as the server)
    names = [n.id for n in site.nodes]
    goals = [p.node for p in site.pois] + [c.node for c in site.charging_stations]
    paths = bench_paths(graph, names, goals, queries)
    any_pair_queries = max(200, queries // 5)
    any_pair, any_pair_cpu = bench_any_pair(graph, names, any_pair_queries)
    comparison: dict[str, Any] = {}
    if peer:
        nx_graph, nx_build_s = peer_graph(graph)
        rng = random.Random(9)
        pairs = [tuple(rng.sample(names, 2)) for _ in range(any_pair_queries)]
        dest_pairs = [(rng.choice(names), rng.choice(goals)) for _ in range(any_pair_queries)]
        ours_any, nx_any, bad_any = bench_peer(graph, nx_graph, pairs)  # type: ignore[arg-type]
        ours_dest, nx_dest, bad_dest = bench_peer(graph, nx_graph, dest_pairs)
        mine_p, theirs_p = percentiles(ours_any), percentiles(nx_any)
        comparison = {
            "peer": {
                "name": "networkx",
                "destination_path_ms": percentiles(nx_dest),
                "any_pair_path_ms": theirs_p,
                "build_s": round(nx_build_s, 3),
            },
            "ratio": {
                "destination_p50": _ratio(
                    percentiles(ours_dest)["p50"], percentiles(nx_dest)["p50"]
                ),
                "any_pair_p50": _ratio(mine_p["p50"], theirs_p["p50"]),
                "any_pair_p99": _ratio(mine_p["p99"], theirs_p["p99"]),
                "build_s": _ratio(warm_s, nx_build_s),
            },
            "agree": bad_any == 0 and bad_dest == 0,
        }
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-") as tmp:
        locks, ws_locks, asked, (stalls, rollout) = asyncio.run(
            bench_locks(site, robots, rate, seconds, ws_robots, followers, Path(tmp))
        )
    ceiling = asyncio.run(saturation(site, robots))
    if not as_json:
        click.echo(
            f"site: {len(site.nodes)} nodes, {len(site.edges)} edges, {len(site.floors)} floors; "
            f"distance fields for {len(goals) + 1} destinations built in {warm_s:.2f} s "
            f"(as the server builds it, tables in two worker processes: {workers_s:.2f} s)"
        )
        click.echo(
            f"path to a destination (distance-field walk): {percentiles(paths)} ms over "
            f"{queries} queries"
        )
        click.echo(
            f"path between any two nodes (elevator transit or a search of one floor): "
            f"{percentiles(any_pair)} ms, CPU {percentiles(any_pair_cpu)} ms"
        )
        click.echo(
            f"locks: {robots} robots asking {rate}/s each ({robots * rate:.0f}/s offered), "
            f"{len(locks) + len(ws_locks)} round trips measured of {asked}; saturation (all "
            f"asking again at once, in-process): {ceiling:.0f} round trips/s"
        )
        click.echo(f"lock round trip, in-process hub endpoints: {percentiles(locks)} ms")
        ws_count = min(ws_robots, robots)
        click.echo(f"lock round trip, {ws_count} WebSocket robots: {percentiles(ws_locks)} ms")
        click.echo(
            "event-loop stalls (longest ms, 99.9th percentile ms, ticks over 20 ms, window s): "
            + ", ".join(
                f"{name} {s['max']} / {s['p999']} / {s['over_20']} / {s['seconds']}"
                for name, s in (
                    ("site publish (PUT JSON)", stalls["publish"]),
                    ("site load (YAML import)", stalls["load"]),
                    ("idle as long", stalls["idle"]),
                )
            )
        )
        if followers:
            click.echo(
                f"site rollout to {followers} robots in another process (publish to the last "
                f"site_loaded): PUT {rollout['publish']} ms, import {rollout['load']} ms"
            )
        click.echo(
            "goals: path p99 < 2 ms, lock round trip p99 < 10 ms, loop stall during a site "
            "load or publish < 20 ms"
        )
    print_result(
        {
            "destination_lookup_ms": percentiles(paths),
            "any_pair_path_ms": percentiles(any_pair),
            "any_pair_path_cpu_ms": percentiles(any_pair_cpu),
            "build_s": round(warm_s, 3),
            "build_workers_s": round(workers_s, 3),
            "lock_rtt_ms": percentiles(locks),
            "idle_max_stall_ms": stalls["idle"]["max"],
            "publish_max_stall_ms": stalls["publish"]["max"],
            "load_max_stall_ms": stalls["load"]["max"],
            "stalls": stalls,
            "rollout_ms": rollout,
            **comparison,
        }
    )


def _ratio(a: float | None, b: float | None) -> float | None:
    return round(a / b, 3) if a is not None and b else None
