"""Visitors' told waits against their real waits: a real server, a real robot agent (bare
simulated base, timed speech, 40x robot time) in the "corridor museum", one tour to learn
from, then three tours queued for the one robot.

    guidebot bench eta --runs 5 --json

Last line: {"runs", "waits", "error_pct": {"p50", "max"}, "within_25_pct", "samples"}.
error_pct: |told - real| / real of each queued tour that waited for another (the second and
third of each run; the first starts at once), told at request time (``eta_s`` of the POST's
answer), real from the request to the task's ``assigned`` event on the hub. within_25_pct:
the share of those waits told within 25 %. samples: [told_s, real_s] each.

A wall-clock figure: the simulated world freezes while its process is stalled (the base steps
at most 0.1 s at a time, robot_agent/sim_base.py) while the server learned its tour lengths a
minute earlier, so a loaded machine stretches waits the estimate cannot know of. That is why
it is measured here, on demand, and not bounded in a test (docs/visitor.md).
"""

from __future__ import annotations

import asyncio
import contextlib
import statistics
import tempfile
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import click
import httpx
import yaml

from backend.auth import Role
from backend.settings import Settings, StaticToken
from backend.testing import RunningServer, running_server
from guidebot.benchutil import print_result
from guidebot.messages import Message
from robot_agent.agent import RobotAgent
from robot_agent.testing import light_robot

__all__ = ["PANEL", "Corridor", "QueueRun", "client", "corridor", "first", "main", "queue_once"]

TIME_SCALE = 40.0
PANEL = "panel-eta-token"

SITE: dict[str, Any] = {
    "name": "Corridor museum",
    "default_language": "en",
    "languages": ["es"],
    "floors": [{"id": "F0"}],
    "nodes": [
        {"id": "home", "floor": "F0", "x": 0, "y": 0},
        {"id": "a", "floor": "F0", "x": 6, "y": 0},
        {"id": "b", "floor": "F0", "x": 14, "y": 0},
        {"id": "c", "floor": "F0", "x": 14, "y": 8},
        {"id": "d", "floor": "F0", "x": 26, "y": 8},
    ],
    "edges": [
        {"a": "home", "b": "a"},
        {"a": "a", "b": "b"},
        {"a": "b", "b": "c"},
        {"a": "c", "b": "d"},
    ],
    "pois": [
        {
            "id": "p1",
            "name": "Vase",
            "node": "a",
            "text": "A vase from the old town, found in a well.",
        },
        {"id": "p2", "name": "Coins", "node": "b", "text": "Silver coins of three kings."},
        {
            "id": "p3",
            "name": "Map",
            "node": "d",
            "text": "The first map of the valley, drawn by a monk over ten long winters.",
            "translations": {"es": {"text": "El primer mapa del valle."}},
        },
    ],
    "tours": [
        {"id": "long", "name": "Long tour", "points": ["p1", "p2", "p3"]},
        {"id": "short", "name": "Short tour", "points": ["p2", "p3"]},
    ],
    "wait_points": [{"id": "w", "node": "home"}],
    "robots": [{"name": "R1", "token": "robot-R1-eta-token", "start_node": "home"}],
}


@dataclass
class Corridor:
    """The corridor museum running: its server, what its hub said and its robots."""

    server: RunningServer
    events: list[Message]
    """Every task_event on the hub, in order."""
    seen_at: dict[str, float]
    """Message id -> loop time it was seen."""
    agents: dict[str, RobotAgent]
    changed: asyncio.Event

    async def until(self, predicate: Callable[[], Any], timeout: float = 60.0) -> None:
        """Check ``predicate`` on every hub task_event, robot_state or robot link change."""
        async with asyncio.timeout(timeout):
            while not predicate():
                self.changed.clear()
                await self.changed.wait()


@contextlib.asynccontextmanager
async def corridor(tmp_path: Path, robots: int = 1) -> AsyncIterator[Corridor]:
    site = dict(SITE)
    site["robots"] = [
        {"name": f"R{i}", "token": f"robot-R{i}-eta-token", "start_node": "home"}
        for i in range(1, robots + 1)
    ]
    site_file = tmp_path / "site.yaml"
    site_file.write_text(yaml.safe_dump(site))
    settings = Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/guidebot.db",
        site=site_file,
        tokens=[StaticToken(token=PANEL, name="panel-eta", role=Role.PANEL)],
    )
    events: list[Message] = []
    async with running_server(settings) as server, contextlib.AsyncExitStack() as stack:
        loop = asyncio.get_running_loop()
        seen_at: dict[str, float] = {}
        changed = asyncio.Event()

        def record(message: Message) -> None:
            if message.type == "task_event":
                seen_at[message.id] = loop.time()
                events.append(message)
            changed.set()

        tap = server.app.state.hub.endpoint("test-tap")
        tap.subscribe("task_event", record, tap=True)
        tap.subscribe("robot_state", record, tap=True)
        tap.subscribe("robot_disconnected", record, tap=True)
        agents: dict[str, RobotAgent] = {}
        for i in range(1, robots + 1):
            agent = light_robot(
                server.url,
                f"R{i}",
                f"robot-R{i}-eta-token",
                site=site_file,
                start_node="home",
                time_scale=TIME_SCALE,
            )
            await stack.enter_async_context(agent)
            agents[f"R{i}"] = agent
        yield Corridor(server, events, seen_at, agents, changed)


def client(server: RunningServer, token: str | None = None) -> httpx.AsyncClient:
    return httpx.AsyncClient(
        base_url=server.url,
        headers={"Authorization": f"Bearer {token or server.admin_token}"},
        timeout=10,
    )


def first(events: list[Message], task_id: str, state: str) -> Message | None:
    return next(
        (e for e in events if e.payload["task_id"] == task_id and e.payload["state"] == state),
        None,
    )


@dataclass
class QueueRun:
    """One run: what three queued tours were told at request time and how long they waited."""

    told: dict[str, float] = field(default_factory=dict)
    """Task id -> ``eta_s`` told at request time, in request order."""
    waits: dict[str, float] = field(default_factory=dict)
    """Task id -> seconds from its request to its ``assigned`` event."""
    warm_history: list[str] = field(default_factory=list)
    """The history events of the tour the server learned from."""
    menu_duration_s: float = 0.0
    """The first tour's duration as the visitor menu told it before anything ran."""

    def errors(self) -> list[float]:
        """|told - real| / real of the tours that waited for another (all but the first)."""
        ids = list(self.told)[1:]
        return [abs(self.told[t] - self.waits[t]) / self.waits[t] for t in ids]


async def queue_once(tmp_path: Path) -> QueueRun:
    """One tour to learn from, then a queue of three (long, short, long) for the one robot."""
    loop = asyncio.get_running_loop()
    run = QueueRun()
    async with corridor(tmp_path) as c, client(c.server, PANEL) as http:
        server, events = c.server, c.events
        menu = (await http.get("/api/visitor")).json()
        run.menu_duration_s = menu["tours"][0]["estimate"]["duration_s"]
        await c.until(lambda: server.app.state.task_manager.robots["R1"].online)
        # One tour to learn from (the server knows nothing of the robots' time scale).
        r = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "long"}})
        r.raise_for_status()
        warm = r.json()["id"]
        await c.until(lambda: first(events, warm, "done") is not None)
        asked_at: dict[str, float] = {}
        for tour in ("long", "short", "long"):
            r = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": tour}})
            r.raise_for_status()
            body = r.json()
            asked_at[body["id"]] = loop.time()
            run.told[body["id"]] = body["eta_s"]
        ids = list(run.told)
        await c.until(lambda: all(first(events, t, "assigned") for t in ids), timeout=90)
        for task_id in ids:
            assigned = first(events, task_id, "assigned")
            assert assigned is not None
            run.waits[task_id] = c.seen_at[assigned.id] - asked_at[task_id]
        async with client(server) as admin:
            history = (await admin.get(f"/api/tasks/{warm}/history")).json()
        run.warm_history = [h["event"] for h in history]
    return run


async def _runs(count: int) -> list[QueueRun]:
    runs = []
    for _ in range(count):
        with tempfile.TemporaryDirectory(prefix="guidebot-bench-eta-") as tmp:
            runs.append(await queue_once(Path(tmp)))
    return runs


@click.command()
@click.option(
    "--runs", default=5, show_default=True, help="Queues of three tours, each on a fresh server."
)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line.")
def main(runs: int, as_json: bool) -> None:
    """How far the waits told at request time were from the real waits."""
    done = asyncio.run(_runs(runs))
    errors = [e for run in done for e in run.errors()]
    samples = [
        [round(run.told[t], 2), round(run.waits[t], 2)] for run in done for t in list(run.told)[1:]
    ]
    if not as_json:
        for told, real in samples:
            click.echo(f"told {told:6.2f} s, waited {real:6.2f} s")
    print_result(
        {
            "runs": runs,
            "waits": len(errors),
            "error_pct": {
                "p50": round(100 * statistics.median(errors), 1),
                "max": round(100 * max(errors), 1),
            },
            "within_25_pct": round(sum(e <= 0.25 for e in errors) / len(errors), 2),
            "samples": samples,
        }
    )
