"""``guidebot bench soak``: the whole fleet under random faults for M minutes, checked all along.

A building simulator, the server (SQLite, or ``--db`` PostgreSQL) and R robot agents with
simulated RoboCAN hardware run as separate processes on loopback (bench/soak_fleet.py), each
robot's link through a relay the soak can cut. Panels (panel tokens) ask for tours and points,
building buttons are pressed, and faults drawn from the seed strike at random times
(bench/soak_faults.py). The referee (bench/soak_watch.py) checks the safety invariants on the
event log, that no task vanishes or fails without a readable reason, that a lock held by a lost
robot is shown to staff, and finally every process's log for unhandled errors. After the last
minute the faults are undone, requests stop, and the fleet is given time to finish its tasks.
docs/robot.md, "Soak benchmark".
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
import shutil
import signal
import tempfile
import time
from collections.abc import Awaitable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import click
import httpx
import yaml

from bench.soak_bookings import SoakBookings, walk_ups
from bench.soak_faults import KINDS, Fault, schedule
from bench.soak_fleet import Child, LinkRelay, free_port, healthy, wait_for
from bench.soak_site import PANELS, robot_token, soak_site, with_ports
from bench.soak_watch import Watch, unhandled_errors
from guidebot.benchutil import print_result
from guidebot.invariants import ALARM_RULES, InvariantChecker

__all__ = ["SoakOptions", "main", "run_soak"]

T = TypeVar("T")
ADMIN = "dev-admin-token"
LOCK_GRACE_S = 30.0
TROUBLE_HOLD_S = 120.0
"""Robot seconds a failed door or lift stays closed (the server's default, docs/server.md)."""
RESUME_WAIT_S = 180.0
"""Wall seconds the soak tries to resume service after a fire alarm is cleared."""


@dataclass
class SoakOptions:
    minutes: float = 1.0
    robots: int = 3
    faults: bool = True
    seed: int = 1
    time_scale: float = 10.0
    db: str | None = None
    fault_every_s: float = 8.0
    fire_alarm: bool = False
    """Deal the ``fire_alarm`` fault too (bench/soak_faults.py)."""
    request_every_s: float = 2.0
    drain_s: float = 180.0
    bookings: int = 0
    """Booked tours spread over the run (bench/soak_bookings.py)."""
    workdir: Path | None = None
    """Keep logs, site and database here (default: a temporary folder, removed)."""


def _log(message: str) -> None:
    click.echo(f"soak: {message}", err=True)


@dataclass
class Soak:
    opts: SoakOptions
    work: Path
    url: str = ""
    control: str = ""
    site: dict[str, Any] = field(default_factory=dict)
    server: Child | None = None
    building: Child | None = None
    robots: dict[str, Child] = field(default_factory=dict)
    relays: dict[str, LinkRelay] = field(default_factory=dict)
    screens: dict[str, str] = field(default_factory=dict)
    injected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(KINDS, 0))
    busy: set[str] = field(default_factory=set)
    """Targets under a fault now (one fault at a time per target)."""
    watch: Watch | None = None
    server_up: bool = True
    t0: float = 0.0

    # --- the fleet -------------------------------------------------------------------------

    async def start(self) -> None:
        o = self.opts
        names = [f"R{i}" for i in range(1, o.robots + 1)]
        self.site = soak_site(o.robots)
        site_file = self.work / "site.yaml"
        site_file.write_text(yaml.safe_dump(self.site, sort_keys=False))
        scale = f"{o.time_scale:g}"
        self.building = Child(
            "building_sim",
            [
                *("building-sim", "--site", str(site_file), "--time-scale", scale),
                *("--port-zero", "--control-port", "0"),
            ],
            self.work / "building_sim.log",
        )
        self.building.start()
        await wait_for("building simulator ready", self.building.ready_json, 60)
        ready = self.building.ready_json() or {}
        self.control = str(ready["control"])
        ports = ready["modules"]
        assert isinstance(ports, dict)
        site_file.write_text(yaml.safe_dump(with_ports(self.site, ports), sort_keys=False))
        port = free_port()
        self.url = f"http://127.0.0.1:{port}"
        db = o.db or f"sqlite+aiosqlite:///{self.work / 'soak.db'}"
        tokens = [{"token": t, "name": n, "role": "panel"} for n, t in PANELS.items()]
        self.server = Child(
            "server",
            [
                *("server", "--port", str(port), "--site", str(site_file), "--db", db),
                *("--log-level", "warning"),
            ],
            self.work / "server.log",
            env={
                "GUIDEBOT_TOKENS": json.dumps(tokens),
                "GUIDEBOT_LOCK_OFFLINE_GRACE_S": f"{LOCK_GRACE_S:g}",
                # A failed door or lift is closed for 120 s of the robots' time, as in a real
                # building: the server's clock is the wall's, the fleet's runs K times faster
                # (unscaled, a 7 s jam closed a door for 20 robot minutes, issue 36).
                "GUIDEBOT_TROUBLE_HOLD_S": f"{TROUBLE_HOLD_S / o.time_scale:g}",
                # Two panels ask for the whole fleet's work: lift their per-panel limit.
                "GUIDEBOT_TASK_REQUESTS_PER_MINUTE": "120",
                "GUIDEBOT_TASK_REQUEST_BURST": "20",
            },
        )
        self.server.start()
        await wait_for("server healthy", lambda: healthy(self.url), 90)
        for name in names:
            relay = LinkRelay(port)
            await relay.start()
            self.relays[name] = relay
            gui_port = free_port()
            self.screens[name] = f"http://127.0.0.1:{gui_port}"
            self.robots[name] = Child(
                name,
                [
                    *("robot", "--name", name, "--server", f"http://127.0.0.1:{relay.port}"),
                    *("--token", robot_token(name), "--simulate", "--time-scale", scale),
                    *("--site", str(site_file), "--gui-port", str(gui_port)),
                    *("--visitor", "yes", "--state-period", "0.5"),
                ],
                self.work / f"{name}.log",
            )
            self.robots[name].start()
        self.watch = Watch(
            self.url, ADMIN, InvariantChecker.from_site(_validated(self.site)), LOCK_GRACE_S
        )
        await wait_for("every robot online", self._all_online, 120, period=1.0)

    async def _all_online(self) -> bool:
        try:
            async with httpx.AsyncClient(timeout=5.0) as http:
                r = await http.get(f"{self.url}/api/robots", headers=_auth(ADMIN))
        except httpx.HTTPError:
            return False
        online = {r["name"] for r in r.json() if r.get("online")} if r.status_code == 200 else set()
        return set(self.robots) <= online

    def children(self) -> list[Child]:
        return [c for c in (self.server, self.building, *self.robots.values()) if c is not None]

    async def stop(self) -> None:
        for child in [*self.robots.values(), self.building, self.server]:
            if child is not None:
                await asyncio.to_thread(child.stop)
        for relay in self.relays.values():
            await relay.stop()

    # --- load ------------------------------------------------------------------------------

    async def load(self, until: float) -> None:
        """Panels ask for tours and points, visitors press the building's buttons."""
        rng = random.Random(self.opts.seed * 7919 + 1)
        tours = [t["id"] for t in self.site["tours"]]
        pois = [p["id"] for p in self.site["pois"]]
        buttons = [b["id"] for b in self.site["buttons"]]
        assert self.watch is not None
        async with httpx.AsyncClient(timeout=10.0) as http:
            while time.monotonic() < until:
                await asyncio.sleep(rng.uniform(0.5, 1.5) * self.opts.request_every_s)
                queued = sum(1 for t in self.watch.tasks.values() if t.state == "queued")
                if queued >= len(self.robots):
                    continue
                with contextlib.suppress(httpx.HTTPError):
                    if rng.random() < 0.3:
                        button = rng.choice(buttons)
                        await http.post(f"{self.control}/buttons/{button}/press", json={"ms": 400})
                        continue
                    panel = rng.choice(list(PANELS))
                    if rng.random() < 0.6:
                        body = {"kind": "tour", "params": {"tour": rng.choice(tours)}}
                    else:
                        body = {"kind": "go_to_poi", "params": {"poi": rng.choice(pois)}}
                    r = await http.post(
                        f"{self.url}/api/tasks", json=body, headers=_auth(PANELS[panel])
                    )
                    if r.status_code == 201:
                        self.watch.expect(r.json()["id"], panel)
                    elif r.status_code not in (429, 503):
                        _log(f"panel request refused: {r.status_code} {r.text[:200]}")

    # --- faults ----------------------------------------------------------------------------

    async def faults(self, plan: list[Fault]) -> None:
        running: set[asyncio.Task[None]] = set()
        try:
            for fault in plan:
                delay = self.t0 + fault.at_s - time.monotonic()
                if delay > 0:
                    await asyncio.sleep(delay)
                task = asyncio.create_task(self._one(fault))
                running.add(task)
                task.add_done_callback(running.discard)
        finally:
            await asyncio.gather(*running, return_exceptions=True)

    async def _one(self, fault: Fault) -> None:
        key = fault.target.split(":")[0] if fault.kind == "can_unplug" else fault.target
        key = f"{fault.kind}:{key}"
        if key in self.busy or (fault.kind == "server_kill" and not self.server_up):
            return
        self.busy.add(key)
        try:
            if await self._inject(fault, undo=False):
                self.injected[fault.kind] += 1
                _log(f"fault {fault}")
                await asyncio.sleep(fault.hold_s)
                await self._inject(fault, undo=True)
        except Exception as exc:  # a fault that could not be injected is reported, not fatal
            _log(f"fault {fault}: {type(exc).__name__}: {exc}")
        finally:
            self.busy.discard(key)

    async def _inject(self, fault: Fault, *, undo: bool) -> bool:
        kind, target = fault.kind, fault.target
        if kind == "robot_kill":
            robot = self.robots[target]
            if not undo:
                robot.kill()
                assert self.watch is not None
                self.watch.checker.forget(target, time.time())
                return True
            robot.restart()
            return True
        if kind == "link_cut":
            relay = self.relays[target]
            relay.restore() if undo else relay.cut()
            return True
        if kind == "server_kill":
            assert self.server is not None
            if not undo:
                self.server_up = False
                self.server.kill()
                return True
            self.server.start()
            await wait_for("server healthy after restart", lambda: healthy(self.url), 120)
            self.server_up = True
            return True
        async with httpx.AsyncClient(timeout=10.0) as http:
            if kind == "fire_alarm":
                return await self._fire_alarm(http, target, undo=undo)
            if kind == "modbus_offline":
                body = {"kind": "none" if undo else "offline"}
                r = await http.post(f"{self.control}/modules/{target}/fault", json=body)
            elif kind == "elevator_stuck":
                r = await http.post(
                    f"{self.control}/elevators/{target}/stuck", json={"stuck": not undo}
                )
            elif kind == "door_jam":
                r = await http.post(f"{self.control}/doors/{target}/jam", json={"jammed": not undo})
            elif kind == "can_unplug":
                name, module = target.split(":")
                plug = {"module_id": int(module, 16), "plugged": undo}
                r = await http.post(f"{self.screens[name]}/sim/module_plug", json=plug)
            elif kind == "battery_panic":
                if undo:
                    return True
                r = await http.post(f"{self.screens[target]}/sim/battery", json={"level": 0.05})
            else:
                raise ValueError(f"unknown fault kind {kind!r}")
        r.raise_for_status()
        return True

    async def _fire_alarm(self, http: httpx.AsyncClient, alarm_id: str, *, undo: bool) -> bool:
        """The alarm input to its alarm value; undone: back to normal, then service resumed as
        a person would, tried again while the server refuses (input not read yet, server or
        module down under another fault)."""
        alarm = next(a for a in self.site["emergency"]["alarms"] if a["id"] == alarm_id)
        ref, active = alarm["input"], int(alarm.get("active_when", 1))
        r = await http.post(
            f"{self.control}/points/{ref['module']}/{ref['point']}",
            json={"value": 1 - active if undo else active},
        )
        r.raise_for_status()
        if not undo:
            return True
        deadline = time.monotonic() + RESUME_WAIT_S
        why = ""
        while time.monotonic() < deadline:
            with contextlib.suppress(httpx.HTTPError):
                r = await http.post(f"{self.url}/api/emergency/resume", headers=_auth(ADMIN))
                if r.status_code == 200:
                    return True
                why = r.text[:200]
                if r.status_code == 409 and "cannot become normal" in why:
                    return True  # already normal (resumed before a server restart, say)
            await asyncio.sleep(0.5)
        assert self.watch is not None
        self.watch.notes.append(f"fire alarm {alarm_id}: service not resumed: {why}")
        return True

    # --- the referee -----------------------------------------------------------------------

    async def referee(self, stop: asyncio.Event) -> None:
        assert self.watch is not None
        last_rss = 0.0
        async with httpx.AsyncClient(timeout=15.0) as http:
            while not stop.is_set():
                if self.server_up:
                    await self.watch.poll(http)
                if time.monotonic() - last_rss > 2.0:
                    last_rss = time.monotonic()
                    self.watch.sample_rss({c.name: c.pid for c in self.children()})
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), 1.0)

    async def drain(self) -> None:
        """No new requests, no faults: give the fleet time to finish what it has."""
        assert self.watch is not None
        deadline = time.monotonic() + self.opts.drain_s
        async with httpx.AsyncClient(timeout=15.0) as http:
            while time.monotonic() < deadline:
                if await self.watch.poll(http) and not self.watch.open_tasks():
                    return
                await asyncio.sleep(1.0)
            await self.watch.poll(http)


def _auth(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _validated(site: dict[str, Any]) -> Any:
    from guidebot.site.validate import validate_site

    return validate_site(site)


async def run_soak(opts: SoakOptions) -> dict[str, Any]:
    """Run the soak; returns the result (the JSON line's object)."""
    work = opts.workdir or Path(tempfile.mkdtemp(prefix="guidebot-soak-"))
    work.mkdir(parents=True, exist_ok=True)
    soak = Soak(opts, work)
    duration = opts.minutes * 60.0
    stuck: dict[str, Any] = {}
    measured: dict[str, Any] = {}
    booked: dict[str, Any] = {}
    try:
        await soak.start()
        assert soak.watch is not None
        bookings = SoakBookings(soak.url, ADMIN, opts.bookings, soak.site)
        await bookings.book(duration)
        names = list(soak.robots)
        plan = (
            schedule(
                opts.seed,
                duration,
                opts.fault_every_s,
                names,
                [m["id"] for m in soak.site["modules"]],
                [e["id"] for e in soak.site["elevators"]],
                [d["id"] for d in soak.site["doors"]],
                alarms=[a["id"] for a in (soak.site.get("emergency") or {}).get("alarms", [])],
                kinds=(*KINDS, "fire_alarm") if opts.fire_alarm else KINDS,
                time_scale=opts.time_scale,
            )
            if opts.faults
            else []
        )
        if opts.fire_alarm:
            soak.injected["fire_alarm"] = 0
        _log(f"{len(plan)} faults planned from seed {opts.seed}; logs in {work}")
        stop = asyncio.Event()
        soak.t0 = time.monotonic()
        referee = asyncio.create_task(soak.referee(stop))
        await asyncio.gather(soak.load(soak.t0 + duration), soak.faults(plan))
        stop.set()
        await referee
        _log("faults over, requests stopped: draining")
        await soak.drain()
        ended = time.time()
        watch = soak.watch
        with contextlib.suppress(httpx.HTTPError):
            async with httpx.AsyncClient(timeout=15.0) as http:
                await watch.poll_histories(http)
        measured = watch.measures.result(
            watch.tasks, list(soak.robots), time.monotonic() - soak.t0, ended
        )
        if opts.bookings:
            with contextlib.suppress(httpx.HTTPError):
                booked = await bookings.measure()
        open_now = watch.open_tasks()
        stuck = {i: t for i, t in open_now.items() if t.state != "queued"}
        for task_id, t in stuck.items():
            watch.notes.append(f"task {task_id} still {t.state} on {t.robot} after the drain")
            robot = soak.robots.get(t.robot or "")
            if robot is not None:  # what that robot was doing, for whoever reads the report
                tail = robot.log.read_text(encoding="utf-8", errors="replace").splitlines()[-25:]
                watch.notes += [f"  {robot.name}.log: {line[:200]}" for line in tail]
    finally:
        await soak.stop()
    watch = soak.watch
    assert watch is not None
    errors = unhandled_errors([c.log for c in soak.children()])
    counts = watch.task_counts()
    counts["tasks_lost"] += len(stuck)
    by_kind = dict.fromkeys(("area", "door", "cabin", *ALARM_RULES), 0)
    for violation in watch.checker.violations:
        by_kind[violation.invariant] += 1
    for line in (
        [str(v) for v in watch.checker.violations] + watch.lock_violations + watch.notes + errors
    ):
        _log(line)
    _log(f"invariant checks: {watch.checker.counts}")
    reasons = watch.failure_reasons()
    _log(f"failure reasons: {reasons}")
    _log(f"touring seconds per robot: {measured.get('touring_s')}")
    memory = {n: (watch.rss_first[n], watch.rss_last[n]) for n in watch.rss_last}
    _log(f"rss first/last MB: {memory}")
    _log(f"restarts: { {c.name: c.restarts for c in soak.children() if c.restarts} }")
    if opts.workdir is None and not (errors or watch.checker.violations or counts["tasks_lost"]):
        shutil.rmtree(work, ignore_errors=True)
    return {
        "minutes": opts.minutes,
        "robots": opts.robots,
        **counts,
        **walk_ups(watch.tasks),
        "area_violations": by_kind["area"] + len(watch.lock_violations),
        "door_violations": by_kind["door"],
        "elevator_violations": by_kind["cabin"],
        "alarm_violations": sum(by_kind[rule] for rule in ALARM_RULES),
        "faults_injected": soak.injected,
        "unhandled_errors": len(errors),
        "max_rss_mb": watch.rss_mb,
        "done_share": measured.get("done_share"),
        "failures_by_reason": reasons,
        "handover_s": measured.get("handover_s"),
        "skipped_stops": measured.get("skipped_stops"),
        "utilisation": measured.get("utilisation"),
        "touring_spread": measured.get("touring_spread"),
        **booked,
    }


async def _until_signal(run: Awaitable[T]) -> T:
    """SIGTERM or SIGINT cancel the run, whose clean-up stops every child (each runs in a
    session of its own, so nothing else would)."""
    task = asyncio.ensure_future(run)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, task.cancel)
    try:
        return await task
    except asyncio.CancelledError:
        raise click.ClickException("interrupted: every process stopped") from None


@click.command()
@click.option("--minutes", type=click.FloatRange(min=0.1), default=5.0, show_default=True)
@click.option("--robots", type=click.IntRange(1, 50), default=5, show_default=True)
@click.option("--faults/--no-faults", default=True, show_default=True)
@click.option("--seed", type=int, default=1, show_default=True)
@click.option("--time-scale", type=click.FloatRange(min=1.0), default=10.0, show_default=True)
@click.option("--db", default=None, help="Database URL (default: SQLite in the work folder).")
@click.option(
    "--fault-every",
    type=click.FloatRange(min=1.0),
    default=8.0,
    show_default=True,
    help="Mean wall seconds between two faults.",
)
@click.option(
    "--fire-alarm/--no-fire-alarm",
    default=False,
    show_default=True,
    help="Deal the fire_alarm fault too: the site's alarm input raised for 20-60 site seconds, "
    "then cleared and service resumed.",
)
@click.option(
    "--drain",
    type=click.FloatRange(min=10.0),
    default=180.0,
    show_default=True,
    help="Wall seconds the fleet gets to finish its tasks after the last minute.",
)
@click.option(
    "--bookings",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Booked tours spread over the run: bookings_on_time_share, bookings_missed.",
)
@click.option(
    "--workdir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Keep logs, site and database here.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the result as one JSON line.")
def main(
    minutes: float,
    robots: int,
    faults: bool,
    seed: int,
    time_scale: float,
    db: str | None,
    fault_every: float,
    fire_alarm: bool,
    drain: float,
    bookings: int,
    workdir: Path | None,
    as_json: bool,
) -> None:
    """The fleet under random faults for M minutes; invariants checked all along."""
    opts = SoakOptions(
        minutes=minutes,
        robots=robots,
        faults=faults,
        seed=seed,
        time_scale=time_scale,
        db=db,
        fault_every_s=fault_every,
        fire_alarm=fire_alarm,
        drain_s=drain,
        bookings=bookings,
        workdir=workdir,
    )
    result = asyncio.run(_until_signal(run_soak(opts)))
    if as_json:
        print_result(result)
    else:
        click.echo(json.dumps(result, indent=2))
