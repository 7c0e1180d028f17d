"""Task Manager benchmark: assignment latency with a long queue and a large fleet.

    guidebot bench tasks --queued 10000 --robots 1000 --json

Last line: {"assign_ms": {"p50", "p99"}, "tasks_per_s": N}.
assign_ms: from a robot's task_ended (or its first robot_state) reaching the Task Manager to
the task_assigned it publishes for that robot: the whole handling, with the queue holding up to
``--queued`` tasks and ``--robots`` robots online, ranking robots by path cost and battery.
tasks_per_s: task_ended -> task_assigned -> task_started cycles per second, with every change
written to a real SQLite database by the write-behind store (as in the server).
"""

from __future__ import annotations

import asyncio
import gc
import random
import tempfile
import time
from pathlib import Path

import click

from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.tasks.manager import TaskManager
from guidebot.benchutil import percentiles, print_result
from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.site.graph import SiteGraph
from guidebot.site.synthetic import synthetic_site

__all__ = ["main"]


async def run(
    nodes: int, queued: int, robots: int, cycles: int, db_dir: Path, echo: bool
) -> dict[str, object]:
    site = synthetic_site(nodes=nodes, robots=robots, areas=10, pois=100)
    graph = SiteGraph(site)
    gc.collect()
    gc.freeze()  # the site and graph live as long as the server: keep them out of GC scans
    engine = make_engine(f"sqlite+aiosqlite:///{db_dir / 'bench.db'}")
    await migrate(engine)
    store = DbStore(make_sessionmaker(engine))
    await store.start()
    bus = Bus()
    # Robots here do not report state at a steady rate: keep them from being declared lost.
    manager = TaskManager(
        bus.endpoint("task_manager"), site, graph=graph, store=store, robot_timeout_s=3600
    )
    await manager.start()
    fleet = bus.endpoint("fleet")
    last_order: dict[str, str] = {}

    def on_assigned(msg: Message) -> None:
        last_order[msg.payload["robot"]] = msg.payload["task_id"]

    fleet.subscribe("task_assigned", on_assigned, tap=True)
    rng = random.Random(3)
    tours = [t.id for t in site.tours]
    pois = [p.id for p in site.pois]

    t0 = time.perf_counter()
    for k in range(queued):
        if k % 2:
            manager.request("tour", {"tour": rng.choice(tours)}, priority=rng.randint(1, 9))
        else:
            manager.request("go_to_poi", {"poi": rng.choice(pois)}, priority=rng.randint(1, 9))
        if k % 500 == 0:
            await asyncio.sleep(0)
    queue_s = time.perf_counter() - t0

    names = [r.name for r in site.robots]
    samples: list[float] = []
    for name in names:  # robots come online: each takes the best task for it
        node = site.robot(name).start_node  # type: ignore[union-attr]
        t1 = time.perf_counter()
        fleet.publish("robot_state", {"robot": name, "node": node, "battery": rng.uniform(0.5, 1)})
        samples.append((time.perf_counter() - t1) * 1000)
        fleet.publish("task_started", {"robot": name, "task_id": last_order[name]})
    await asyncio.sleep(0)

    busy = [n for n in names if n in last_order]
    done = 0
    t2 = time.perf_counter()
    while done < cycles and len(manager.queue):
        name = rng.choice(busy)
        task_id = last_order[name]
        t1 = time.perf_counter()
        fleet.publish("task_ended", {"robot": name, "task_id": task_id, "outcome": "done"})
        samples.append((time.perf_counter() - t1) * 1000)
        new = last_order[name]
        if new == task_id or manager.tasks[new].internal:
            raise RuntimeError(f"{name} got no queued task after ending {task_id}")
        fleet.publish("task_started", {"robot": name, "task_id": new})
        done += 1
        if done % 100 == 0:
            await asyncio.sleep(0)  # let the database writer run, as the server's loop does
    cycle_s = time.perf_counter() - t2
    await manager.stop()
    t3 = time.perf_counter()
    await store.stop()
    flush_s = time.perf_counter() - t3
    await engine.dispose()
    if echo:
        click.echo(
            f"site {len(site.nodes)} nodes; queued {queued} tasks in {queue_s:.2f} s "
            f"({queued / queue_s:.0f}/s); {len(names)} robots online; {done} end->assign cycles "
            f"in {cycle_s:.2f} s; final database flush {flush_s:.2f} s; rows dropped "
            f"{store.dropped}"
        )
        click.echo("goal: assignment p99 < 5 ms")
    return {"assign_ms": percentiles(samples), "tasks_per_s": round(done / cycle_s, 1)}


@click.command()
@click.option("--queued", default=10_000, show_default=True, help="Tasks waiting at the start.")
@click.option("--robots", default=1000, show_default=True, help="Robots online.")
@click.option("--nodes", default=10_000, show_default=True, help="Nodes of the synthetic site.")
@click.option("--cycles", default=5000, show_default=True, help="task_ended cycles to time.")
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line on stdout.")
def main(queued: int, robots: int, nodes: int, cycles: int, as_json: bool) -> None:
    """Assignment latency and throughput of the Task Manager."""
    if queued < robots + 1 or robots < 1 or cycles < 1:
        raise click.UsageError("need robots >= 1, cycles >= 1 and queued > robots")
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-") as tmp:
        result = asyncio.run(run(nodes, queued, robots, cycles, Path(tmp), not as_json))
    print_result(result)
