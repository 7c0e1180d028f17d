"""``guidebot bench emergency``: the fire alarm, end to end, on a real fleet (issue 35).

The building simulator's Modbus/TCP modules run in this process (so T1, the alarm input changed
at the module, is an exact instant), the central server and ``--robots`` robot agent processes
with simulated RoboCAN hardware run on loopback at ``--time-scale``. Each run gives every robot
a ``go_to`` task, lets them get under way, raises the site's alarm input, waits until every
robot is at its safe spot (or stuck for good), clears the input, resumes service as a person
would (``POST /api/emergency/resume``), waits for the cut-off tasks to start again, and cancels
what is left. Everything is read back from the server's event log (GET /api/events):

- ``alarm_to_stop_ms``: T1 -> every robot's first zero-velocity frame on its CAN bus (the
  robot's ``stopped_at``, stamped by a tap that runs once the base sent the frame), the slowest
  robot of each run;
- ``clear_s``: T1 -> every robot at a safe spot or out of every escape route (a robot that was
  in none is clear once stopped; one in a route, once it reached a node out of it);
- ``safe_s``: T1 -> every robot at its safe spot;
- ``resume_s``: the resume request -> every task the alarm cut off started again;
- ``violations``: the safety invariants (guidebot/invariants.py, the alarm's rules included)
  over the whole event log.

``--site demo`` is the demo museum with a dock per robot (the soak's venue); ``--site
synthetic`` a two-floor corridor grid of ``--nodes`` nodes with three elevators, a corridor
escape route per floor, six safe spots per floor and one alarm input for the whole site.
docs/emergency.md, "Measured".
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import random
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import click
import httpx
import yaml

from bench.reaction import _robots, _wait_fleet
from bench.robot import _server_process
from bench.soak import _until_signal
from bench.soak_site import soak_site
from guidebot.benchutil import percentiles, print_result
from guidebot.invariants import InvariantChecker

__all__ = ["demo_site", "main", "synthetic_emergency_site"]

log = logging.getLogger(__name__)

SAFE_WAIT_S = 240.0
"""Wall seconds a run waits for every robot to be safe (or stuck for good)."""
RESUME_WAIT_S = 120.0
UNDER_WAY_S = 30.0
"""Wall seconds a run waits for half the robots to pass a node before it raises the alarm."""
IN_ROUTE_S = 20.0
"""Every other run then waits up to this long for a robot in an escape route."""
FINAL = {"done", "failed", "cancelled"}


def _robot_token(name: str) -> str:
    return f"robot-{name}-bench-token"  # what bench.reaction._robots gives each process


def demo_site(robots: int) -> dict[str, Any]:
    """The demo museum with a dock per robot off the entrance (bench/soak_site.py)."""
    site = soak_site(robots)
    for robot in site["robots"]:
        robot["token"] = _robot_token(robot["name"])
    return site


def synthetic_emergency_site(nodes: int, robots: int, seed: int = 1) -> dict[str, Any]:
    """A two-floor synthetic site (guidebot.site.synthetic) given an ``emergency`` part: a
    corridor escape route across each floor (the grid's column at a third of its width), six
    safe spots a floor, either side of it, and a fire alarm input for the whole site."""
    from guidebot.site.synthetic import synthetic_site

    floors = 2
    doc: dict[str, Any] = synthetic_site(
        nodes=nodes, robots=robots, areas=robots, pois=20, floors=floors, seed=seed
    ).model_dump(mode="json", exclude_none=True)
    side = math.ceil(math.sqrt(nodes / floors))
    column = side // 3
    mid = side // 2
    route = {f: [f"n{f}_{column}_{j}" for j in range(side)] for f in range(floors)}
    spots = [
        f"n{f}_{i}_{j}"
        for f in range(floors)
        for i, j in (
            (1, 1),
            (1, side - 2),
            (side - 2, 1),
            (side - 2, side - 2),
            (max(0, column - 2), mid),
            (min(side - 1, column + 2), mid),
        )
    ]
    taken = {n for nodes_ in route.values() for n in nodes_} | set(spots)
    doc["areas"] = [a for a in doc["areas"] if not set(a["nodes"]) & taken]
    doc["areas"] += [{"id": f"escape_{f}", "nodes": route[f]} for f in range(floors)]
    doc["pois"] = [p for p in doc["pois"] if p["node"] not in taken]
    kept = {p["id"] for p in doc["pois"]}
    doc["tours"] = [
        {**t, "points": [p for p in t["points"] if p in kept]}
        for t in doc["tours"]
        if any(p in kept for p in t["points"])
    ]
    doc["modules"].append(
        {
            "id": "fire_panel",
            "port": 0,
            "points": [{"name": "fire_alarm", "address": 1, "kind": "discrete_input"}],
        }
    )
    doc["emergency"] = {
        "alarms": [
            {"id": "fire_all", "input": {"module": "fire_panel", "point": "fire_alarm"}, "zone": {}}
        ],
        "safe_spots": spots,
        "escape_routes": [f"escape_{f}" for f in range(floors)],
        "words": {"en": "Fire alarm. Please follow the exit signs. I will wait out of the way."},
    }
    rng = random.Random(seed)
    free = [
        n["id"]
        for n in doc["nodes"]
        if n["id"] not in taken and not n["id"].startswith("lift") and n["floor"] == "F0"
    ]
    doc["robots"] = [
        {"name": f"R{i}", "token": _robot_token(f"R{i}"), "start_node": node}
        for i, node in enumerate(rng.sample(free, robots), 1)
    ]
    doc["name"] = f"Emergency bench, synthetic {len(doc['nodes'])} nodes"
    return doc


def site_problems(doc: dict[str, Any]) -> list[str]:
    """What ``guidebot site check`` says about the bench's site (it must say nothing)."""
    from guidebot.site.validate import SiteInvalid, validate_site

    try:
        validate_site(doc)
    except SiteInvalid as exc:
        return [f"{i.loc}: {i.message}" for i in exc.issues]
    return []


@dataclass
class Run:
    """What one run measured (seconds from T1 unless said)."""

    stop_s: list[float] = field(default_factory=list)
    """Each robot's first zero-velocity frame."""
    clear_s: float | None = None
    safe_s: float | None = None
    resume_s: float | None = None
    stuck: int = 0
    missing_stop: int = 0
    declared_s: float | None = None
    """The server declared the alarm (its event's time): poll, filter and the server's part."""


@dataclass
class Bench:
    http: httpx.AsyncClient
    sim: Any
    alarm: Any
    """The alarm input's IORef."""
    active: int
    site: dict[str, Any]
    checker: InvariantChecker
    rng: random.Random
    after_id: int = 0
    names: list[str] = field(default_factory=list)

    async def events(self) -> list[dict[str, Any]]:
        """The event log since the last call, fed to the invariant checker."""
        out: list[dict[str, Any]] = []
        while True:
            r = await self.http.get(
                "/api/events", params={"after_id": self.after_id, "limit": 1000}
            )
            r.raise_for_status()
            page = r.json()
            out += page["events"]
            self.after_id = page["next_after_id"]
            if len(page["events"]) < 1000:
                break
        self.checker.feed_events(out)
        return out

    def in_routes(self) -> list[str]:
        """The robots whose last reported node is in an escape route."""
        return [r for r, n in self.checker.position.items() if n in self.checker.escape_at]

    async def emergency(self) -> dict[str, Any]:
        r = await self.http.get("/api/emergency")
        r.raise_for_status()
        result: dict[str, Any] = r.json()
        return result

    async def give_work(self) -> list[str]:
        """A go_to task per robot, to a random node of a floor with robots."""
        targets = [
            n["id"]
            for n in self.site["nodes"]
            if n["id"] not in self.checker.cabin_at
            and not n["id"].startswith("dock")
            and n["id"] not in self.checker.escape_at
            and n["id"] not in self.checker.door_at
        ]
        ids = []
        for _ in self.names:
            body = {"kind": "go_to", "params": {"node": self.rng.choice(targets)}}
            r = await self.http.post("/api/tasks", json=body)
            r.raise_for_status()
            ids.append(str(r.json()["id"]))
        return ids

    async def task_state(self, task_id: str) -> str:
        r = await self.http.get(f"/api/tasks/{task_id}")
        r.raise_for_status()
        return str(r.json()["state"])

    async def one(self) -> Run:
        run = Run()
        work = await self.give_work()
        # Under way: half the robots past a node of their way, then a random moment.
        moved: set[str] = set()
        deadline = time.monotonic() + UNDER_WAY_S
        while len(moved) < (len(self.names) + 1) // 2 and time.monotonic() < deadline:
            await asyncio.sleep(0.2)
            moved |= {
                str(e["data"].get("robot"))
                for e in await self.events()
                if e["kind"] == "node_reached"
            }
        if self.rng.random() < 0.5:
            # Every other run, when a robot is in an escape route (the case clear_s is about).
            deadline = time.monotonic() + IN_ROUTE_S
            while not self.in_routes() and time.monotonic() < deadline:
                await asyncio.sleep(0.1)
                await self.events()
        else:
            await asyncio.sleep(self.rng.uniform(0.0, 2.0))
        await self.events()
        raised = time.time()
        self.sim.write(self.alarm, self.active)
        # Every robot safe, or stuck for good (its third try failed).
        deadline = time.monotonic() + SAFE_WAIT_S
        while time.monotonic() < deadline:
            robots = (await self.emergency())["robots"]
            done = [
                r
                for r in robots.values()
                if r.get("state") == "safe"
                or (r.get("state") == "stuck" and "attempt 3 of 3" in str(r.get("why")))
                or (r.get("state") in ("ordered", "stuck") and not r.get("path"))
            ]
            if len(done) == len(self.names):
                break
            await asyncio.sleep(0.2)
        events = await self.events()
        self._measure(run, raised, events)
        # The building's alarm is reset, then a person resumes service.
        self.sim.write(self.alarm, 1 - self.active)
        deadline = time.monotonic() + 30
        while (await self.emergency())["state"] != "input_clear":
            if time.monotonic() > deadline:
                raise RuntimeError("the alarm input read normal, but no input_clear in 30 s")
            await asyncio.sleep(0.05)
        asked = time.time()
        r = await self.http.post("/api/emergency/resume")
        r.raise_for_status()
        cut_off = [str(t) for t in r.json()["resumed_tasks"]]
        deadline = time.monotonic() + RESUME_WAIT_S
        waiting = set(cut_off)
        while waiting and time.monotonic() < deadline:
            waiting = {t for t in waiting if await self.task_state(t) in ("queued", "assigned")}
            if waiting:
                await asyncio.sleep(0.1)
        run.resume_s = None if waiting else time.time() - asked
        for task_id in work:
            with contextlib.suppress(httpx.HTTPError):
                await self.http.post(f"/api/tasks/{task_id}/cancel", json={"reason": "bench"})
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            states = [await self.task_state(t) for t in work]
            if all(s in FINAL for s in states):
                break
            await asyncio.sleep(0.2)
        await self.events()
        return run

    def _measure(self, run: Run, raised: float, events: list[dict[str, Any]]) -> None:
        stopped: dict[str, float] = {}
        safe: dict[str, float] = {}
        for e in events:
            data = e.get("data") or {}
            if e["kind"] == "emergency_declared" and run.declared_s is None:
                run.declared_s = float(e["at"]) - raised
            if e["kind"] != "robot_evacuation":
                continue
            robot = str(data.get("robot"))
            if data.get("state") == "stopped" and data.get("stopped_at") is not None:
                stopped.setdefault(robot, float(data["stopped_at"]))
            elif data.get("state") == "safe":
                safe.setdefault(robot, float(e["at"]))
        run.stop_s = [stopped[n] - raised for n in self.names if n in stopped]
        run.missing_stop = sum(1 for n in self.names if n not in stopped)
        run.stuck = sum(1 for n in self.names if n not in safe)
        if not run.missing_stop and not run.stuck:
            run.safe_s = max(safe.values()) - raised
        clear: list[float] = []
        for name in self.names:
            line = self.checker.positions.get(name)
            at_alarm = line.at(raised) if line is not None else None
            when = safe.get(name)
            if at_alarm is not None and at_alarm in self.checker.escape_at:
                assert line is not None
                out = next(
                    (
                        t
                        for t, n in line.changes(raised, math.inf)
                        if n not in self.checker.escape_at
                    ),
                    None,
                )
                when = min(x for x in (when, out) if x is not None) if (when or out) else None
            elif name in stopped:
                when = stopped[name]
            if when is not None:
                clear.append(when - raised)
        if len(clear) == len(self.names):
            run.clear_s = max(clear)


async def _experiment(
    site_kind: str, robots: int, runs: int, nodes: int, time_scale: float, seed: int
) -> tuple[list[Run], InvariantChecker]:
    from building_sim.simulator import BuildingSimulator
    from guidebot.site.building import IORef
    from guidebot.site.building_config import load_building
    from guidebot.site.validate import validate_site

    data = demo_site(robots) if site_kind == "demo" else synthetic_emergency_site(nodes, robots)
    if problems := site_problems(data):
        raise click.ClickException("the bench's site fails its check: " + "; ".join(problems))
    alarm_doc = data["emergency"]["alarms"][0]
    alarm = IORef(**alarm_doc["input"])
    active = int(alarm_doc.get("active_when", 1))
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-emergency-") as tmp:
        sim = BuildingSimulator(load_building(data), time_scale=time_scale, port_zero=True)
        async with sim:
            for module in data["modules"]:
                module["port"] = sim.ports[module["id"]]
            site_file = Path(tmp) / "site.yaml"
            site_file.write_text(yaml.safe_dump(data, sort_keys=False))
            checker = InvariantChecker.from_site(validate_site(data))
            async with (
                _server_process(tmp, site_file) as server,
                _robots(server.url, site_file, robots, time_scale),
                httpx.AsyncClient(
                    base_url=server.url,
                    headers={"Authorization": f"Bearer {server.admin_token}"},
                    timeout=15,
                ) as http,
            ):
                await _wait_fleet(http, robots)
                bench = Bench(
                    http,
                    sim,
                    alarm,
                    active,
                    data,
                    checker,
                    random.Random(seed),
                    names=[r["name"] for r in data["robots"]],
                )
                await bench.events()
                results = []
                for i in range(runs):
                    results.append(await bench.one())
                    log.warning("run %d of %d: %s", i + 1, runs, results[-1])
    return results, checker


def summarise(
    runs: list[Run], checker: InvariantChecker, site_kind: str, robots: int, nodes: int
) -> dict[str, Any]:
    """The JSON result: the issue's keys first."""

    def stats(values: list[float], scale: float = 1.0, digits: int = 2) -> dict[str, Any]:
        scaled = [v * scale for v in values]
        return (
            {**percentiles(scaled, digits=digits), "max": round(max(scaled), digits)}
            if (scaled)
            else {"p50": None, "p99": None, "max": None}
        )

    per_run_stop = [max(r.stop_s) for r in runs if r.stop_s and not r.missing_stop]
    by_rule: dict[str, int] = {}
    for v in checker.violations:
        by_rule[v.invariant] = by_rule.get(v.invariant, 0) + 1
    return {
        "site": site_kind,
        "nodes": len(checker.floor_of),
        "robots": robots,
        "runs": len(runs),
        "alarm_to_stop_ms": stats(per_run_stop, 1000.0, 1),
        "clear_s": stats([r.clear_s for r in runs if r.clear_s is not None]),
        "resume_s": stats([r.resume_s for r in runs if r.resume_s is not None]),
        "violations": len(checker.violations),
        "violations_by_rule": by_rule,
        "robot_stop_ms": stats([s for r in runs for s in r.stop_s], 1000.0, 1),
        "safe_s": stats([r.safe_s for r in runs if r.safe_s is not None]),
        "steps_ms": {
            "input_to_declared": stats(
                [r.declared_s for r in runs if r.declared_s is not None], 1000.0, 1
            ),
            "declared_to_last_stop": stats(
                [
                    max(r.stop_s) - r.declared_s
                    for r in runs
                    if r.stop_s and r.declared_s is not None
                ],
                1000.0,
                1,
            ),
        },
        "runs_not_all_safe": sum(1 for r in runs if r.stuck),
        "stops_not_seen": sum(r.missing_stop for r in runs),
        "checked": {k: v for k, v in checker.counts.items() if k != "events"},
    }


@click.command()
@click.option("--robots", type=click.IntRange(1, 50), default=20, show_default=True)
@click.option("--runs", type=click.IntRange(min=1), default=20, show_default=True)
@click.option(
    "--site",
    "site_kind",
    type=click.Choice(["demo", "synthetic"]),
    default="demo",
    show_default=True,
    help="The demo museum (a dock per robot) or a two-floor synthetic grid of --nodes.",
)
@click.option("--nodes", type=click.IntRange(50, 20_000), default=2000, show_default=True)
@click.option(
    "--time-scale",
    type=click.FloatRange(min=1.0),
    default=1.0,
    show_default=True,
    help="Robots' and building's time scale; clear_s and safe_s are wall seconds.",
)
@click.option("--seed", type=int, default=1, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line on stdout.")
def main(
    robots: int,
    runs: int,
    site_kind: str,
    nodes: int,
    time_scale: float,
    seed: int,
    as_json: bool,
) -> None:
    """Fire alarm input -> every robot stopped, clear of the escape routes, safe; resume."""
    logging.basicConfig(level=logging.WARNING)  # one line a run, on stderr
    results, checker = asyncio.run(
        _until_signal(_experiment(site_kind, robots, runs, nodes, time_scale, seed))
    )
    result = summarise(results, checker, site_kind, robots, nodes)
    if not as_json:
        for v in checker.violations:
            click.echo(str(v), err=True)
    with contextlib.suppress(BrokenPipeError):
        print_result(result)
