"""``guidebot plan --live --virtual``, its child process: the live run on virtual time. The
building simulator, the server (``create_app``: Task Manager, Traffic Manager,
BuildingInterface, hub, event log) and bare simulated robot agents run on one event loop whose
clock jumps to the next timer whenever every task waits (``backend.planning.vtime``), all at
time scale 1, talking over loopback sockets as in service. The visitors are the live run's
``_Driver``. Nothing waits on the wall clock, so the outcome is in exact simulated seconds and
the wall time is only the CPU the fleet needs. docs/planning.md, "The virtual run".

It runs as a process of its own (``backend.planning.virtual`` starts it, through
``bench.plan_virtual_run``, which switches the clock before the product is imported): the server
and the robot agent meet only over the bus, never in one import, and ``time.time`` is patched
only there.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import os
import secrets
import shutil
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import yaml

from backend.auth import Role
from backend.planning.live import LiveOptions, _Driver, _fleet_entries, _outcome
from backend.planning.measure import read_events
from backend.planning.profile import PlanError, Request
from backend.planning.sim import Outcome
from backend.planning.vtime import installed, virtual_time
from backend.settings import Settings, StaticToken
from backend.testing import running_server
from bench.plan_modbus import in_process_modbus
from building_sim.simulator import BuildingSimulator
from guidebot.site.building_config import BuildingConfig
from guidebot.site.schema import Site
from guidebot.site.yamlio import load_site_file
from robot_agent.agent import AgentConfig, RobotAgent
from robot_agent.gui import OnboardScreen

__all__ = ["EPOCH", "main", "play"]

EPOCH = 1_800_000_000.0
"""The virtual clock's epoch seconds at the start of every run (the same for each: a run is
repeatable)."""
STATE_PERIOD_S = 1.0
"""The robots' robot_state period: ``guidebot robot``'s default, as a robot in service and the
busy demo the plan is checked against (the live run sends twice as many, as the soak)."""
SWEEP_S = 600.0
"""Seconds between two sweeps of people's expired sessions (the server's: every 5 s). Nobody
signs in during a plan (it uses tokens), so the sweep finds nothing; every 5 s it was a
database transaction, 7 200 of them in a 10-hour day."""
ALARM_POLL_MS = 1000
"""The period of the fire alarm input's own read (the server's: 50 ms, for the alarm's speed,
docs/emergency.md). A plan sounds no alarm, and each module's poll (200 ms on the demo site)
still reads the input; every 50 ms it was 720 000 reads in a 10-hour day."""
POLL_S = 0.5
"""Simulated seconds between the visitors' looks at the screens and the clock: an answer comes
2.5 to 3 s after its question (the live run at 10x: 2.5 to 3.5 s)."""
STATES_S = 2.0
"""Simulated seconds between two reads of the tours' states (a tour's first question comes
tens of seconds after it starts)."""
ONLINE_S = 60.0
"""Simulated seconds the robots may take to come online."""


class _NoProcesses:
    """The driver's view of the run's processes: there are none to die."""

    def dead(self) -> str | None:
        return None


def play(
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
    """Play ``requests`` on a fleet of ``robots`` in virtual time (call with no running loop,
    in a process started by ``bench.plan_virtual_run``)."""
    if not installed():
        # The product's clock=time.time defaults would read the real clock (vtime's docstring).
        raise PlanError("virtual run: start it with python -m bench.plan_virtual_run")
    opts = options or LiveOptions()
    started, cpu = time.perf_counter(), time.process_time()
    outcome = virtual_time(
        _play(site_path, site, requests, robots, day_s, patience_s, queue_limit, opts),
        epoch=EPOCH,
    )
    outcome.wall_s = time.perf_counter() - started
    # The CPU the run took (this process, its threads included): the wall time on a machine
    # nobody else uses.
    outcome.extra["cpu_s"] = round(time.process_time() - cpu, 1)
    return outcome


async def _play(
    site_path: Path,
    site: Site,
    requests: Sequence[Request],
    robots: int,
    day_s: float,
    patience_s: float | None,
    queue_limit: int | None,
    opts: LiveOptions,
) -> Outcome:
    base = opts.workdir or Path(tempfile.mkdtemp(prefix="guidebot-plan-"))
    folder = base / f"virtual-{robots}"
    folder.mkdir(parents=True, exist_ok=True)
    # The components' warnings go to the run's log, as each process's do in the live run.
    handler = logging.FileHandler(folder / "run.log", encoding="utf-8")
    handler.setLevel(logging.WARNING)
    handler.setFormatter(logging.Formatter("%(created).3f %(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        with tempfile.TemporaryDirectory(prefix="guidebot-plan-", dir=_fast_dir()) as scratch:
            db_file = Path(scratch) / "plan.db"
            outcome = await _serve(
                site_path,
                site,
                requests,
                robots,
                day_s,
                patience_s,
                queue_limit,
                opts,
                folder,
                db_file,
            )
            shutil.copyfile(db_file, folder / "plan.db")
    finally:
        root.removeHandler(handler)
        handler.close()
    return outcome


def _fast_dir() -> str | None:
    """A folder in memory for the database (/dev/shm), else the system's temporary folder: the
    loop waits for each commit's fsync in real time, and on a disk those add up."""
    shm = Path("/dev/shm")
    return str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None


async def _serve(
    site_path: Path,
    site: Site,
    requests: Sequence[Request],
    robots: int,
    day_s: float,
    patience_s: float | None,
    queue_limit: int | None,
    opts: LiveOptions,
    folder: Path,
    db_file: Path,
) -> Outcome:
    db = f"sqlite+aiosqlite:///{db_file}"
    panel = secrets.token_hex(16)
    config = BuildingConfig(
        modules=site.modules, doors=site.doors, elevators=site.elevators, buttons=site.buttons
    )
    async with BuildingSimulator(config, time_scale=1.0, port_zero=True) as building:
        data: dict[str, Any] = site.model_dump(mode="json")
        for module in data["modules"]:
            module["port"] = building.ports[module["id"]]
        data["robots"] = _fleet_entries(site, robots)
        served = folder / "site.yaml"
        served.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        settings = Settings(
            db_url=db,
            site=served,
            site_dir=site_path.parent,
            hub_ws_port=0,
            access_log=False,
            log_level="warning",
            tokens=[StaticToken(token=panel, name="plan-panel", role=Role.PANEL)],
            # One panel asks for a whole day's tours.
            task_requests_per_minute=100000,
            task_request_burst=10000,
            site_workers=0,
        )
        with in_process_modbus(building), _quiet_housekeeping(), _spoken_once():
            async with running_server(settings) as server:
                agents = [_agent(server.hub_url, entry, served) for entry in data["robots"]]
                try:
                    for agent in agents:
                        await agent.__aenter__()
                    import httpx

                    # Idle connections are dropped well before the servers' keep-alive (5 s)
                    # ends: in virtual time a request can come at the very instant the server
                    # closes one.
                    limits = httpx.Limits(keepalive_expiry=1.0)
                    async with httpx.AsyncClient(timeout=30.0, limits=limits) as http:
                        await _online(http, server.url, server.admin_token, robots)
                        screens = {agent.config.name: _screen(agent) for agent in agents}
                        opts.log(f"a fleet of {robots} online (virtual time)")
                        driver = _Visitors(
                            http, server.url, server.admin_token, panel, screens, requests, opts
                        )
                        driver.scale, driver.poll_s, driver.states_s = 1.0, POLL_S, STATES_S
                        driver.patience_s, driver.queue_limit = patience_s, queue_limit
                        t0 = time.time()
                        await driver.run(day_s, _NoProcesses())  # type: ignore[arg-type]
                        t_end = time.time()
                finally:
                    for agent in reversed(agents):
                        await agent.__aexit__(None, None, None)
    events = await read_events(db)
    outcome = _outcome(
        events, site, driver, robots=robots, day_s=day_s, t0=t0, t_end=t_end, scale=1.0, wall_s=0.0
    )
    outcome.extra["mode"] = "virtual"
    outcome.extra.pop("time_scale", None)
    return outcome


@contextlib.contextmanager
def _quiet_housekeeping() -> Iterator[None]:
    """The server's watches that have nothing to find in a plan, less often (``SWEEP_S``,
    ``ALARM_POLL_MS``)."""
    from backend.accounts import component
    from backend.building import interface

    saved = component.SWEEP_EVERY_S, interface.ALARM_POLL_MS
    component.SWEEP_EVERY_S, interface.ALARM_POLL_MS = SWEEP_S, ALARM_POLL_MS
    try:
        yield
    finally:
        component.SWEEP_EVERY_S, interface.ALARM_POLL_MS = saved


@contextlib.contextmanager
def _spoken_once() -> Iterator[None]:
    """The robots speak as in service and in the busy demo: ``guidebot robot``'s default speech
    engine, espeak-ng where it is installed, whose audio's length is how long the robot talks
    (where it is not, the length is estimated from the text, as on such a robot). Its synthesis
    runs in a process of its own, in real time: the virtual clock stands still while it works
    (counted as thread work, ``backend.planning.vtime``), and each text is synthesised once per
    run (a pure function of the text, the voice and the rate)."""
    from robot_agent.speech import Speech

    saved = Speech._duration
    lengths: dict[tuple[str, str | None, float], float] = {}

    async def duration(self: Speech, text: str, voice: str | None) -> float:
        key = (text, voice, self.dwell)
        if key not in lengths:
            clock = getattr(asyncio.get_running_loop(), "clock", None)
            if clock is not None:
                clock.busy(1)
            try:
                lengths[key] = await saved(self, text, voice)
            finally:
                if clock is not None:
                    clock.busy(-1)
        return lengths[key]

    Speech._duration = duration  # type: ignore[method-assign]
    try:
        yield
    finally:
        Speech._duration = saved  # type: ignore[method-assign]


def _agent(hub_url: str, entry: dict[str, Any], site_file: Path) -> RobotAgent:
    """A bare simulated robot with a simulated battery on its clock (no RoboCAN: its reader
    threads would not follow virtual time)."""
    return RobotAgent(
        AgentConfig(
            name=entry["name"],
            server=hub_url,
            token=entry["token"],
            can=None,
            time_scale=1.0,
            start_node=entry["start_node"],
            max_speed=entry["max_speed_mps"],
            battery_low=entry["battery_low"],
            battery_panic=entry["battery_panic"],
            bare_battery=True,
            speech_engine="auto",
            state_period_s=STATE_PERIOD_S,
            site=site_file,
            gui_port=0,
        )
    )


def _screen(agent: RobotAgent) -> OnboardScreen:
    if agent.screen is None:
        raise PlanError(f"virtual run: robot {agent.config.name} has no touch screen")
    return agent.screen


class _Visitors(_Driver):
    """The live run's visitors (``_Driver``: the same requests, answers and patience), who look
    at the robots' touch screens and touch them in-process: the plan owns both ends, and this
    is what the screen's ``GET /api/screen`` and ``POST /api/answer`` call. Over HTTP, looking
    at two screens every half second of every tour was the run's largest cost after the
    Modbus polls. Their requests to the server stay HTTP, as a visitor panel's."""

    def __init__(
        self,
        http: Any,
        url: str,
        admin: str,
        panel: str,
        screens: dict[str, OnboardScreen],
        requests: Sequence[Request],
        opts: LiveOptions,
    ) -> None:
        super().__init__(http, url, admin, panel, list(screens), requests, opts)
        self.onboard = screens

    async def _look(self) -> list[dict[str, Any] | None]:
        return [self.onboard[name].screen(None) for name in self.screens]

    async def _touch(self, screen: str, answer: str) -> bool:
        return self.onboard[screen].answer("yes" if answer == "yes" else "no")


async def _online(http: Any, url: str, admin: str, robots: int) -> None:
    headers = {"Authorization": f"Bearer {admin}"}
    deadline = time.monotonic() + ONLINE_S
    while time.monotonic() < deadline:
        r = await http.get(f"{url}/api/robots", headers=headers)
        if r.status_code == 200 and sum(1 for x in r.json() if x.get("online")) >= robots:
            return
        await asyncio.sleep(0.5)
    raise PlanError(f"virtual run: the robots were not online within {ONLINE_S:g} s")


def main(argv: Sequence[str] | None = None) -> int:
    """Read the job (``backend.planning.virtual.job``), play it, write the outcome."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 2:
        print("usage: python -m bench.plan_virtual_run JOB.json OUTCOME.json", file=sys.stderr)
        return 2
    job = json.loads(Path(args[0]).read_text(encoding="utf-8"))
    site_path = Path(job["site"])
    options = LiveOptions(
        virtual=True,
        can=False,
        workdir=Path(job["workdir"]),
        log=lambda line: print(f"plan: {line}", file=sys.stderr, flush=True),
    )
    try:
        outcome = play(
            site_path,
            load_site_file(site_path),
            [Request(**r) for r in job["requests"]],
            robots=int(job["robots"]),
            day_s=float(job["day_s"]),
            patience_s=job["patience_s"],
            queue_limit=job["queue_limit"],
            options=options,
        )
    except PlanError as exc:
        Path(args[1]).write_text(json.dumps({"error": str(exc)}), encoding="utf-8")
        return 1
    Path(args[1]).write_text(json.dumps(dataclasses.asdict(outcome)), encoding="utf-8")
    return 0
