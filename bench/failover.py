"""Fail-over benchmark: SIGKILL the leader of two server processes, again and again.

    guidebot bench failover --db postgresql+asyncpg://... --broker redis://... --json

Two `guidebot server --broker` processes on 127.0.0.1 (the demo site, no building modules)
share the given database and Redis. Each round: robots R1 and R2 connect to the follower; R1
asks for the restricted corridor, is granted it by the leader (through the broker) and reports
standing in it; ``--tasks`` tasks are created through the leader's REST API (each acknowledged
with its id); the leader is SIGKILLed; once the follower serves as the new leader, R1 and R2
resync (robot_state) and R2 asks for the corridor, which R1 still holds. Then R1 leaves and R2
must get it. The killed process is started again as a follower for the next round.

Last line: {"leader_kill_to_new_leader_ms": {"p50", "p99", "max"}, "tasks_lost": N,
"double_grants": N, "kills": K}.
leader_kill_to_new_leader_ms: SIGKILL to the new leader serving with all its components up
("serving" in /api/health, polled every 50 ms).
tasks_lost: acknowledged tasks the new leader does not list.
double_grants: rounds in which R2 was granted the corridor while R1 held it.
With ``--pause`` the leader is frozen (SIGSTOP) instead: the other process leads once the
frozen one's lease has run out (GUIDEBOT_LEADER_LEASE_S, 1.5 s here), and the frozen one is
resumed while R2 asks: fenced, it grants nothing, and it exits (75) on finding its lock gone.
"""

from __future__ import annotations

import asyncio
import tempfile
import time
from pathlib import Path
from typing import Any

import click
import httpx

from guidebot.benchutil import percentiles, print_result

from .cluster_clients import AreaRobot
from .servers import ADMIN_TOKEN, ServerProcess, start_servers, wait_until

__all__ = ["main"]

_AUTH = {"Authorization": f"Bearer {ADMIN_TOKEN}"}


async def _leader(servers: list[ServerProcess]) -> ServerProcess:
    async def find() -> ServerProcess | None:
        for server in servers:
            health = await server.health()
            if health and health["cluster"]["serving"]:
                return server
        return None

    found: ServerProcess = await wait_until(find, 60, "a leader")
    return found


async def _round(servers: list[ServerProcess], tasks: int, pause: bool) -> tuple[float, int, int]:
    leader = await _leader(servers)
    other = next(s for s in servers if s is not leader)
    r1, r2 = await AreaRobot.connect(other, "R1"), await AreaRobot.connect(other, "R2")
    try:
        took_ms, lost = await _kill_leader(leader, other, tasks, r1, pause)
        if pause:  # the frozen leader wakes, past its lease: fenced, it finds its lock gone
            leader.resume()
        # The new leader knows nothing of the corridor but what the robots resync.
        await r1.report("corridor_w", holding=True)
        await r2.report("charge_b", holding=False)
        await r2.ask()
        await r1.synced()  # a grant R2 would get is on its way by now
        await r2.synced()
        doubled = 1 if r2.grants() else 0
        await r1.report("hall", holding=False)
        await r1.release()
        await r2.granted(1, "R2's grant once R1 left the corridor", timeout=60)
        await r2.release()
        if pause:
            await asyncio.to_thread(leader.process.wait, 60)
    finally:
        await r1.close()
        await r2.close()
    leader.stop()
    revived = ServerProcess(leader.name, leader.db_url, leader.broker_url, leader.log_path)
    servers[servers.index(leader)] = revived
    await wait_until(revived.ready, 60, f"{leader.name} to come back")
    return took_ms, lost, doubled


async def _kill_leader(
    leader: ServerProcess, other: ServerProcess, tasks: int, holder: AreaRobot, pause: bool
) -> tuple[float, int]:
    """``holder`` takes the corridor, tasks are acknowledged, the leader is killed: the time
    to a new leader serving, and how many acknowledged tasks it does not know."""
    before = holder.grants()
    await holder.ask()
    await holder.granted(before + 1, f"{holder.name}'s grant from {leader.name}")
    await holder.report("corridor_w", holding=True)
    async with httpx.AsyncClient(headers=_AUTH, timeout=10) as http:
        created = []
        for _ in range(tasks):
            answer = await http.post(
                f"{leader.url}/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}}
            )
            answer.raise_for_status()
            created.append(answer.json()["id"])
        killed_at = time.monotonic()
        leader.pause() if pause else leader.kill()

        async def leads() -> bool:
            health = await other.health()
            return bool(health and health["cluster"]["serving"])

        await wait_until(leads, 60, f"{other.name} to lead", interval=0.05)
        took_ms = (time.monotonic() - killed_at) * 1000
        listed = await http.get(f"{other.url}/api/tasks", params={"limit": 1000})
        listed.raise_for_status()
        known = {t["id"] for t in listed.json()["tasks"]}
    return took_ms, sum(1 for task_id in created if task_id not in known)


async def run(
    db_url: str, broker_url: str, kills: int, tasks: int, pause: bool = False
) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="guidebot-failover-") as root:
        async with start_servers(["p0", "p1"], db_url, broker_url, Path(root)) as servers:
            samples, lost, doubled = [], 0, 0
            for _ in range(kills):
                took_ms, lost_now, doubled_now = await _round(servers, tasks, pause)
                samples.append(took_ms)
                lost += lost_now
                doubled += doubled_now
    return {
        "leader_kill_to_new_leader_ms": {**percentiles(samples), "max": round(max(samples), 1)},
        "tasks_lost": lost,
        "double_grants": doubled,
        "kills": kills,
        "mode": "pause" if pause else "kill",
    }


@click.command()
@click.option(
    "--db", "db_url", required=True, help="postgresql+asyncpg:// URL (an empty database)."
)
@click.option("--broker", "broker_url", required=True, help="redis:// URL.")
@click.option("--kills", default=5, show_default=True, help="Leader kills (rounds).")
@click.option("--tasks", default=5, show_default=True, help="Tasks created before each kill.")
@click.option(
    "--pause",
    is_flag=True,
    help="SIGSTOP the leader instead (resumed once the other leads): fail-over by its lease.",
)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line on stdout.")
def main(db_url: str, broker_url: str, kills: int, tasks: int, pause: bool, as_json: bool) -> None:
    """SIGKILL the leader of two server processes; time the fail-over, count lost tasks and
    double grants of one area."""
    result = asyncio.run(run(db_url, broker_url, kills, tasks, pause))
    if not as_json:
        click.echo(f"{kills} leader kills with {tasks} tasks each (median, p99 and max ms):")
    print_result(result)
