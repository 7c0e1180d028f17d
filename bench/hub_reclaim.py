"""The hub's GC reclaim (backend/hub/memory.py): what many robots leaving at once costs the
server's event loop, and what the reclaim pass that follows costs.

    guidebot bench reclaim --nodes 10000 --clients 100 --json

A running server holds a synthetic site of ``--nodes`` nodes; ``--clients`` of its robots
connect from another process (bench/site_followers.py) and the hub freezes their objects; then
the process ends and they all leave at once. Last line: {"nodes", "clients",
"freeze_ms" (the freeze after they connected: a collection of what is not frozen yet, then
``gc.freeze()``), "leave_max_stall_ms" (the longest stall of the server's loop from the leave
until the hub has detached them all), "reclaim_ms" (the reclaim's own pass: a collection of what
is not frozen, then a freeze; it never walks the frozen site),
"reclaim_max_stall_ms" (the longest stall while waiting for it: the pass, on its own timer),
"reclaims"}. ``--quiet-s`` sets how long the hub waits for clients to settle before it
reclaims (default: the server's 5 s; shorter than the leave itself, the reclaim runs inside the
leave's window). A reclaim needs at least 64 clients gone.
"""

from __future__ import annotations

import asyncio
import tempfile
import time
from pathlib import Path
from typing import Any

import click

from backend.settings import Settings
from backend.testing import RunningServer, running_server
from bench.traffic import site_followers
from guidebot.benchutil import LoopStall, print_result
from guidebot.site.synthetic import synthetic_site
from guidebot.site.yamlio import dump_site

__all__ = ["bench_reclaim", "main"]

WAIT_S = 120.0
"""How long each phase may take before the bench fails."""


async def until(condition: Any, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        if time.monotonic() > deadline:
            raise RuntimeError(f"not within {WAIT_S:g} s: {what}")
        await asyncio.sleep(0.01)


async def bench_reclaim(
    server: RunningServer, tokens: list[tuple[str, str]], quiet_s: float
) -> dict[str, Any]:
    """Connect ``tokens``' robots, let the hub freeze, make them all leave: the stalls."""
    hub = server.app.state.hub
    memory = hub.memory
    memory.quiet_s = quiet_s
    names = {name for name, _ in tokens}
    async with site_followers(server.ws_url, tokens):
        await until(lambda: names <= set(hub.bus.remote), "every robot connected")
        freezes = memory.freezes
        await until(lambda: memory.freezes > freezes, "the hub froze their objects")
        leave = LoopStall()
        await leave.__aenter__()
    await until(lambda: not names & set(hub.bus.remote), "every robot detached")
    await leave.__aexit__(None, None, None)
    async with LoopStall() as reclaim:
        await until(lambda: memory.reclaims > 0, "the reclaim ran")
    return {
        "freeze_ms": round(memory.last_freeze_s * 1000, 1),
        "leave_max_stall_ms": round(leave.max_ms, 1),
        "reclaim_ms": round(memory.last_reclaim_s * 1000, 1),
        "reclaim_max_stall_ms": round(reclaim.max_ms, 1),
        "reclaims": memory.reclaims,
    }


async def run(nodes: int, clients: int, quiet_s: float) -> dict[str, Any]:
    site = synthetic_site(nodes=nodes, robots=clients)
    with tempfile.TemporaryDirectory() as tmp:
        site_file = Path(tmp) / "site.yaml"
        site_file.write_text(dump_site(site))
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{Path(tmp) / 'bench.db'}",
            site=site_file,
            building_enabled=False,
        )
        async with running_server(settings, start_timeout=300) as server:
            tokens = [(r.name, r.token) for r in site.robots]
            return {"nodes": len(site.nodes), "clients": clients} | await bench_reclaim(
                server, tokens, quiet_s
            )


@click.command()
@click.option("--nodes", default=10_000, show_default=True, help="Nodes of the synthetic site.")
@click.option("--clients", default=100, show_default=True, help="Robots that leave at once.")
@click.option(
    "--quiet-s", default=5.0, show_default=True, help="The hub's settle time (the server's)."
)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line on stdout.")
def main(nodes: int, clients: int, quiet_s: float, as_json: bool) -> None:
    """The hub's GC reclaim after many robots leave: the loop's stalls."""
    if clients < 64:
        raise click.UsageError("--clients is at least 64 (the hub reclaims after 64 have left)")
    result = asyncio.run(run(nodes, clients, quiet_s))
    if not as_json:
        click.echo(
            f"{clients} robots left: loop stalled at most {result['leave_max_stall_ms']} ms;"
            f" the reclaim after it took {result['reclaim_ms']} ms"
        )
    print_result(result)
