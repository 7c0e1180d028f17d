"""``guidebot plan --live``: a day of visitors played on the real thing. The building simulator,
the server (its Task Manager and Traffic Manager) and one simulated robot agent per robot run as
processes on loopback, robots and building ``scale`` times faster than the wall clock, as the
soak runs them; the planner asks for each tour at its time (scaled) with a visitor panel's
token, answers each "continue the tour?" as that group would (yes until the point it leaves
after), cancels a request whose group ran out of patience, then reads the server's event log.
Lock and elevator waits, doors, batteries and charging (with ``can``: the robots' simulated
RoboCAN battery) and anything the real fleet does are in the outcome because the real fleet did
them. docs/planning.md, "The live run"."""

from __future__ import annotations

import asyncio
import json
import os
import secrets
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import yaml

from backend.planning.measure import read_events, tallies, tour_ends, tour_waits
from backend.planning.profile import PlanError, Request
from backend.planning.sim import Outcome, fleet
from backend.reports.rollup import node_positions
from guidebot.demo_site import site_with_ports
from guidebot.processes import spawn_guidebot, stop_process
from guidebot.site.schema import Site

__all__ = ["FATES", "LiveOptions", "request_fates", "run_live"]

ANSWER_S = 2.5
"""Simulated seconds a group takes to answer "continue the tour?" (the demo's visitors: 1 to 4)."""
POLL_S = 0.1
"""Wall seconds between two looks at the robots' screens and the clock."""
START_S = 120.0
"""Wall seconds each process may take to start (a loaded machine)."""
LEAD_S = 60.0
"""Simulated seconds the fleet runs before the first request (the time before is skipped: a
recorded day's first request may come late in its first hour)."""
FINAL = ("done", "failed", "cancelled")


@dataclass
class LiveOptions:
    scale: float = 10.0
    """Robots and building run this many times faster than the wall clock."""
    can: bool = True
    """Simulated RoboCAN modules on each robot (its battery: charging is in the day); False: a
    bare simulated base (lighter, no battery)."""
    drain_s: float = 3600.0
    """Simulated seconds after the day for the last tours to end."""
    workdir: Path | None = None
    """Keep each run's logs, site and database here (default: a temporary folder)."""
    virtual: bool = False
    """Run in one process on virtual time (``backend.planning.virtual``) instead of scaled wall
    time: exact simulated seconds, bare robots (``scale`` and ``can`` do not apply)."""
    log: Callable[[str], None] = field(default=lambda _: None)


@dataclass
class _Child:
    name: str
    process: subprocess.Popen[bytes]


class _Processes:
    """The run's processes, stopped robots first, then the server, then the building."""

    def __init__(self, folder: Path, env: dict[str, str]) -> None:
        self.folder, self.env = folder, env
        self.children: list[_Child] = []

    def spawn(self, name: str, *args: str) -> _Child:
        with (self.folder / f"{name}.log").open("ab") as out:
            process = spawn_guidebot(list(args), stdout=out, stderr=subprocess.STDOUT, env=self.env)
        child = _Child(name, process)
        self.children.append(child)
        return child

    def dead(self) -> str | None:
        for child in self.children:
            if child.process.poll() is not None:
                return f"{child.name} exited (code {child.process.returncode}); see {self.folder}"
        return None

    def stop(self) -> None:
        for child in reversed(self.children):
            stop_process(child.process, 10.0)


async def _until(what: str, check: Callable[[], Any], procs: _Processes) -> Any:
    """Poll ``check`` (sync or async) until it gives something; PlanError on a dead process or
    after START_S."""
    deadline = time.monotonic() + START_S
    while time.monotonic() < deadline:
        if (why := procs.dead()) is not None:
            raise PlanError(f"live run: {why}")
        result = check()
        if asyncio.iscoroutine(result):
            result = await result
        if result:
            return result
        await asyncio.sleep(0.2)
    raise PlanError(f"live run: {what} not within {START_S:g} s (see {procs.folder})")


def _fleet_entries(site: Site, size: int) -> list[dict[str, Any]]:
    """The site file's ``robots`` for a fleet of ``size``: the site's own, then copies of the
    last one (the pure model's ``fleet``: same names, start nodes and speeds), each with a
    token of its own."""
    entries = []
    for name, info in fleet(site, size).items():
        known = site.robot(name)
        token = known.token if known is not None else f"plan-{name}-{secrets.token_hex(8)}"
        config = info.config
        entries.append(
            {
                "name": name,
                "token": token,
                "start_node": info.node,
                "max_speed_mps": config.max_speed_mps,
                "battery_low": config.battery_low,
                "battery_panic": config.battery_panic,
            }
        )
    return entries


async def run_live(
    site_path: Path,
    site: Site,
    requests: Sequence[Request],
    *,
    robots: int,
    day_s: float,
    patience_s: float | None = None,
    queue_limit: int | None = None,
    options: LiveOptions | None = None,
) -> Outcome:
    """Play ``requests`` on a live fleet of ``robots``; the outcome in simulated seconds, with
    ``extra``: lock and elevator waits, charging, busiest areas and doors, faults, failures."""
    opts = options or LiveOptions()
    if opts.scale <= 0:
        raise PlanError(f"--time-scale {opts.scale:g}: must be above 0")
    base = opts.workdir or Path(tempfile.mkdtemp(prefix="guidebot-plan-"))
    folder = base / f"robots-{robots}"
    folder.mkdir(parents=True, exist_ok=True)
    db = f"sqlite+aiosqlite:///{folder / 'plan.db'}"
    admin, panel = secrets.token_hex(16), secrets.token_hex(16)
    env = dict(os.environ)
    env.update(
        GUIDEBOT_ADMIN_TOKEN=admin,
        GUIDEBOT_TOKENS=json.dumps([{"token": panel, "name": "plan-panel", "role": "panel"}]),
        # One panel asks for a whole day's tours, faster than the wall clock.
        GUIDEBOT_TASK_REQUESTS_PER_MINUTE="100000",
        GUIDEBOT_TASK_REQUEST_BURST="10000",
    )
    procs = _Processes(folder, env)
    scale = f"{opts.scale:g}"
    started = time.perf_counter()
    try:
        procs.spawn(
            "building_sim",
            *("building-sim", "--site", str(site_path), "--time-scale", scale),
            *("--port-zero", "--control-port", "0"),
        )
        ready = await _until("the building simulator", lambda: _ready(folder), procs)
        ports = {str(k): int(v) for k, v in dict(ready["modules"]).items()}
        served = site_with_ports(site_path, ports, folder / "site")
        data = yaml.safe_load(served.read_text(encoding="utf-8"))
        data["robots"] = _fleet_entries(site, robots)
        served.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        port = _free_port()
        url = f"http://127.0.0.1:{port}"
        procs.spawn(
            "server",
            *("server", "--port", str(port), "--hub-ws-port", "0", "--site", str(served)),
            *("--db", db, "--no-access-log", "--log-level", "warning"),
        )
        async with httpx.AsyncClient(timeout=10.0) as http:
            health = await _until("the server", lambda: _health(http, url), procs)
            hub = f"ws://127.0.0.1:{health['hub_ws_port']}/ws"
            screens: dict[str, str] = {}
            for entry in data["robots"]:
                name, gui = entry["name"], _free_port()
                screens[name] = f"http://127.0.0.1:{gui}"
                args = ["robot", "--name", name, "--server", hub, "--token", entry["token"]]
                args += ["--time-scale", scale, "--site", str(served), "--gui-port", str(gui)]
                args += ["--state-period", "0.5", "--log-level", "warning"]
                args += ["--simulate", "--can", f"virtual:{name}"] if opts.can else ["--no-can"]
                procs.spawn(name, *args)
            await _until(
                "every robot online", lambda: _online(http, url, admin, set(screens)), procs
            )
            opts.log(f"a fleet of {robots} online at {scale}x; playing {len(requests)} requests")
            driver = _Driver(http, url, admin, panel, list(screens.values()), requests, opts)
            driver.patience_s, driver.queue_limit = patience_s, queue_limit
            t0 = time.time()
            await driver.run(day_s, procs)
            t_end = time.time()
    finally:
        await asyncio.to_thread(procs.stop)
    return _outcome(
        await read_events(db),
        site,
        driver,
        robots=robots,
        day_s=day_s,
        t0=t0,
        t_end=t_end,
        scale=opts.scale,
        wall_s=time.perf_counter() - started,
    )


def _ready(folder: Path) -> dict[str, Any] | None:
    """The building simulator's first line, once written: {"ready", "control", "modules"}."""
    try:
        line = (folder / "building_sim.log").read_text(encoding="utf-8").partition("\n")
    except OSError:
        return None
    if not line[1]:
        return None
    try:
        ready = json.loads(line[0])
    except ValueError:
        return None
    return ready if isinstance(ready, dict) and ready.get("ready") else None


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _health(http: httpx.AsyncClient, url: str) -> dict[str, Any] | None:
    try:
        r = await http.get(f"{url}/api/health")
    except httpx.HTTPError:
        return None
    return dict(r.json()) if r.status_code == 200 else None


async def _online(http: httpx.AsyncClient, url: str, admin: str, names: set[str]) -> bool:
    try:
        r = await http.get(f"{url}/api/robots", headers={"Authorization": f"Bearer {admin}"})
    except httpx.HTTPError:
        return False
    return r.status_code == 200 and names <= {x["name"] for x in r.json() if x.get("online")}


class _Driver:
    """The visitors of the day: they ask for tours, answer the robots, and give up."""

    def __init__(
        self,
        http: httpx.AsyncClient,
        url: str,
        admin: str,
        panel: str,
        screens: list[str],
        requests: Sequence[Request],
        opts: LiveOptions,
    ) -> None:
        self.http, self.url, self.screens, self.requests = http, url, screens, requests
        self.admin = {"Authorization": f"Bearer {admin}"}
        self.panel = {"Authorization": f"Bearer {panel}"}
        self.scale, self.drain_s, self.log = opts.scale, opts.drain_s, opts.log
        self.patience_s: float | None = None
        self.queue_limit: int | None = None
        self.poll_s = POLL_S
        """Wall seconds between two looks at the screens and the clock."""
        self.states_s = 0.5
        """Wall seconds between two reads of the tours' states."""
        self.task_of: dict[str, int] = {}
        """Task id -> the request's index."""
        self.state: dict[str, str] = {}
        self.refused: list[int] = []
        self.abandoned: list[int] = []
        self.unfinished = 0
        self.answered: dict[str, int] = {}
        self._asked: dict[str, tuple[str, str, float]] = {}
        """screen -> (question id, task id, when to answer (monotonic))"""
        self._give_up: list[tuple[float, str]] = []
        first = min((r.at for r in requests), default=0.0)
        self.skipped_s = max(0.0, first - LEAD_S)
        """Simulated seconds of the day skipped before the first request (LEAD_S before it)."""

    def _sim(self, t0: float) -> float:
        return (time.monotonic() - t0) * self.scale + self.skipped_s

    async def run(self, day_s: float, procs: _Processes) -> None:
        t0 = time.monotonic()
        order = sorted(range(len(self.requests)), key=lambda i: self.requests[i].at)
        nxt, last_states = 0, 0.0
        while True:
            if (why := procs.dead()) is not None:
                raise PlanError(f"live run: {why}")
            now = self._sim(t0)
            while nxt < len(order) and self.requests[order[nxt]].at <= now:
                await self._ask(order[nxt], t0)
                nxt += 1
            await self._screens()
            await self._patience()
            if time.monotonic() - last_states >= self.states_s:
                last_states = time.monotonic()
                await self._states()
                if nxt == len(order) and all(s in FINAL for s in self.state.values()):
                    return
            if now > day_s + self.drain_s:
                self.unfinished = sum(1 for s in self.state.values() if s not in FINAL)
                self.log(
                    f"{self.unfinished} tours still unfinished {self.drain_s:g} s after the day"
                )
                return
            await asyncio.sleep(self.poll_s)

    async def _ask(self, i: int, t0: float) -> None:
        if self.queue_limit is not None:
            waiting = sum(1 for s in self.state.values() if s == "queued")
            if waiting >= self.queue_limit:
                self.refused.append(i)
                return
        body = {"kind": "tour", "params": {"tour": self.requests[i].tour}}
        r = await self.http.post(f"{self.url}/api/tasks", json=body, headers=self.panel)
        if r.status_code != 201:
            raise PlanError(
                f"live run: the server refused a tour request: {r.status_code} {r.text[:200]}"
            )
        task = str(r.json()["id"])
        self.task_of[task] = i
        self.state[task] = "queued"
        if self.patience_s is not None:
            self._give_up.append((time.monotonic() + self.patience_s / self.scale, task))

    async def _states(self) -> None:
        open_ids = [t for t, s in self.state.items() if s not in FINAL]
        if not open_ids:
            return
        r = await self.http.get(
            f"{self.url}/api/tasks",
            params={"include_internal": "false", "limit": 1000},
            headers=self.admin,
        )
        r.raise_for_status()
        for task in r.json()["tasks"]:
            if task["id"] in self.state:
                self.state[task["id"]] = task["state"]

    async def _patience(self) -> None:
        now = time.monotonic()
        due = [task for at, task in self._give_up if at <= now]
        self._give_up = [(at, task) for at, task in self._give_up if at > now]
        for task in due:
            r = await self.http.get(f"{self.url}/api/tasks/{task}", headers=self.admin)
            seen = r.json() if r.status_code == 200 else {}
            # Only a group no robot ever came for gives up (a tour requeued after its robot
            # dropped out has its group already with it).
            if seen.get("state") == "queued" and seen.get("started_at") is None:
                c = await self.http.post(f"{self.url}/api/tasks/{task}/cancel", headers=self.admin)
                if c.status_code == 200:
                    self.abandoned.append(self.task_of[task])
                    self.state[task] = "cancelled"

    async def _screens(self) -> None:
        if not any(s in ("assigned", "running") for s in self.state.values()):
            return  # no tour under way: no screen asks anything
        now = time.monotonic()
        for screen, shown in zip(self.screens, await self._look(), strict=True):
            if shown is None:
                continue
            question, task = shown.get("question"), shown.get("task") or {}
            if not question:
                self._asked.pop(screen, None)
                continue
            qid, task_id = str(question.get("id")), str(task.get("id"))
            asked = self._asked.get(screen)
            if asked is None or asked[0] != qid:
                self._asked[screen] = (qid, task_id, now + ANSWER_S / self.scale)
                continue
            if now < asked[2]:
                continue
            done = self.answered.get(task_id, 0)
            i = self.task_of.get(task_id)
            follow = self.requests[i].follow if i is not None else 1_000
            answer = "yes" if done + 1 < follow else "no"
            if await self._touch(screen, answer):
                self.answered[task_id] = done + 1
                del self._asked[screen]

    async def _look(self) -> list[dict[str, Any] | None]:
        """What each robot's touch screen shows (``GET /api/screen``; None: no answer)."""
        replies = await asyncio.gather(
            *(self.http.get(f"{s}/api/screen") for s in self.screens), return_exceptions=True
        )
        return [
            None if isinstance(r, BaseException) or r.status_code != 200 else r.json()
            for r in replies
        ]

    async def _touch(self, screen: str, answer: str) -> bool:
        """Touch ``answer`` on a screen (``POST /api/answer``); False if it was not taken."""
        try:
            r = await self.http.post(f"{screen}/api/answer", json={"answer": answer})
        except httpx.HTTPError:
            return False
        return r.status_code < 300


FATES = ("served", "refused", "abandoned", "failed", "skipped", "unfinished")
"""What became of a request: each is exactly one (docs/planning.md, its JSON keys)."""


def request_fates(
    requests: int,
    *,
    refused: set[int],
    abandoned: set[int],
    task_of: dict[str, int],
    served: set[int],
    ended: dict[str, str],
) -> dict[str, int]:
    """How many requests (indexes ``0..requests-1``) had each of ``FATES``, so that they add up
    to ``requests``: refused; served (its robot reached the tour's first point; a group that
    gave up as it arrived was served); abandoned (the group gave up first); then, by how its
    tour ended (``ended``: task id -> its last end event): failed (``task_failed``, or
    cancelled by the server), skipped (``task_done`` without ever reaching the first point: the
    Task Manager skipped it, a door or lift on the way out of order), unfinished (still queued
    or under way when the run stopped, or never asked)."""
    task_by_index = {i: task for task, i in task_of.items()}
    counts = dict.fromkeys(FATES, 0)
    for i in range(requests):
        task = task_by_index.get(i)
        end = ended.get(task) if task is not None else None
        if i in refused:
            fate = "refused"
        elif i in served:
            fate = "served"
        elif i in abandoned:
            fate = "abandoned"
        elif end in ("task_failed", "task_cancelled"):
            fate = "failed"
        elif end == "task_done":
            fate = "skipped"
        else:
            fate = "unfinished"
        counts[fate] += 1
    return counts


def _outcome(
    events: list[Any],
    site: Site,
    driver: _Driver,
    *,
    robots: int,
    day_s: float,
    t0: float,
    t_end: float,
    scale: float,
    wall_s: float,
) -> Outcome:
    """The run's outcome in simulated seconds (wall seconds since ``t0`` times ``scale``, plus
    the skipped start of the day)."""
    waits, _, _ = tour_waits(events)
    out = Outcome(robots=robots, policy="nearest", requests=len(driver.requests), day_s=day_s)
    for task, i in driver.task_of.items():
        if task in waits:
            out.wait_of[i] = waits[task] * scale
    out.waits_s = [out.wait_of[i] for i in sorted(out.wait_of)]
    fates = request_fates(
        len(driver.requests),
        refused=set(driver.refused),
        abandoned=set(driver.abandoned),
        task_of=driver.task_of,
        served=set(out.wait_of),
        ended=tour_ends(events),
    )
    out.refused, out.abandoned = fates["refused"], fates["abandoned"]
    ends = [
        at
        for at, kind, _, d in events
        if kind in ("task_done", "task_failed", "task_cancelled")
        and str(d.get("task_id")) in driver.task_of
    ]
    out.last_end_s = (max(ends) - t0) * scale + driver.skipped_s if ends else 0.0
    sums = tallies(events, node_positions(site), t_end)
    robot_time: dict[str, float] = {}
    for key, (_, total) in sums.get("robot_time", {}).items():
        state = key.rpartition("|")[2]
        robot_time[state] = robot_time.get(state, 0.0) + total * scale
    out.busy_s = robot_time.get("touring", 0.0)
    out.wall_s = wall_s

    def waited(metric: str) -> dict[str, dict[str, float]]:
        return {
            key: {"count": int(n), "total_s": round(total * scale, 1)}
            for key, (n, total) in sorted(sums.get(metric, {}).items())
        }

    def busiest(metric: str) -> list[dict[str, Any]]:
        ranked = sorted(sums.get(metric, {}).items(), key=lambda kv: (-kv[1][0], kv[0]))
        return [{"name": key, "count": int(n)} for key, (n, _) in ranked[:10]]

    out.extra = {
        "mode": "live",
        "time_scale": scale,
        "failed": fates["failed"],
        "skipped": fates["skipped"],
        "unfinished": fates["unfinished"],
        "lock_wait": waited("lock_wait"),
        "lock_wait_s": round(sum(v[1] for v in sums.get("lock_wait", {}).values()) * scale, 1),
        "elevator_wait": waited("elevator_wait"),
        "elevator_wait_s": round(
            sum(v[1] for v in sums.get("elevator_wait", {}).values()) * scale, 1
        ),
        "charging_s": round(robot_time.get("charging", 0.0), 1),
        "robot_time_s": {k: round(v, 1) for k, v in sorted(robot_time.items())},
        "busiest_areas": busiest("area_granted"),
        "busiest_doors": busiest("door_opened"),
        "faults": int(sum(v[0] for v in sums.get("faults", {}).values())),
        "door_blocks": int(sum(v[0] for v in sums.get("door_blocks", {}).values())),
    }
    return out
