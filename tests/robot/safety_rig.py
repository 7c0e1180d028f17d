"""A safety test venue and a fleet running on it: real server, real Modbus/TCP, real links.

The site (``safety_site``): two floors, doors D0 (ground) and D1 (first), two elevators
(lift_a west, lift_b east), two corridors back to back (corr_a, corr_b) between passing places.

    home1..3 ─ hall ─ door0 ─ west ─ ca1 ─ ca2 ─ cb1 ─ cb2 ─ east          (F0)
                │              │    └─ corr_a ─┘└─ corr_b ─┘    │
               la0           w_dock                            lb0
    (F1)       la1 ─ up_w ─────── door1 ────────────── up_e ─ lb1

``fleet(...)`` starts the building simulator, the server (its own BuildingInterface polls the
simulator), and one robot agent per robot (bare simulated base, real WebSocket link); every hub
message feeds an InvariantChecker.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import yaml

from backend.settings import Settings
from backend.testing import RunningServer, running_server
from building_sim.simulator import BuildingSimulator
from guidebot.invariants import InvariantChecker
from guidebot.messages import Message
from guidebot.site.building_config import load_building
from guidebot.site.validate import validate_site
from robot_agent.agent import AgentConfig, RobotAgent

ROBOT_SCALE = 10.0
BUILDING_SCALE = 10.0


def _node(id_: str, floor: str, x: float, y: float, **extra: Any) -> dict[str, Any]:
    return {"id": id_, "floor": floor, "x": x, "y": y, **extra}


def safety_site() -> dict[str, Any]:
    f0 = [
        _node("home1", "F0", 0, 0),
        _node("home2", "F0", 0, 3),
        _node("home3", "F0", 0, -3),
        _node("hall", "F0", 5, 0, passing_place=True),
        _node("door0", "F0", 9, 0),
        _node("west", "F0", 13, 0, passing_place=True),
        _node("w_dock", "F0", 13, 4),
        _node("ca1", "F0", 17, 0),
        _node("ca2", "F0", 21, 0),
        _node("cb1", "F0", 25, 0),
        _node("cb2", "F0", 29, 0),
        _node("east", "F0", 33, 0, passing_place=True),
        _node("la0", "F0", 5, 5),
        _node("lb0", "F0", 33, 5),
    ]
    f1 = [
        _node("la1", "F1", 5, 5),
        _node("up_w", "F1", 5, 0, passing_place=True),
        _node("door1", "F1", 19, 0),
        _node("up_e", "F1", 33, 0, passing_place=True),
        _node("lb1", "F1", 33, 5),
    ]
    chain = ["hall", "door0", "west", "ca1", "ca2", "cb1", "cb2", "east"]
    edges = [{"a": a, "b": b} for a, b in itertools.pairwise(chain)]
    edges += [{"a": h, "b": "hall"} for h in ("home1", "home2", "home3")]
    edges += [
        {"a": "west", "b": "w_dock"},
        {"a": "hall", "b": "la0"},
        {"a": "east", "b": "lb0"},
        {"a": "la1", "b": "up_w"},
        {"a": "up_w", "b": "door1"},
        {"a": "door1", "b": "up_e"},
        {"a": "up_e", "b": "lb1"},
    ]

    def points(m: str) -> list[dict[str, Any]]:
        return [
            {"name": f"d{m}_open", "address": 0, "kind": "coil"},
            {"name": "la_call", "address": 1, "kind": "coil"},
            {"name": "lb_call", "address": 2, "kind": "coil"},
            {"name": f"d{m}_is_open", "address": 0, "kind": "discrete_input"},
            {"name": "la_here", "address": 1, "kind": "discrete_input"},
            {"name": "lb_here", "address": 2, "kind": "discrete_input"},
        ]

    def lift(id_: str, p: str, node: str) -> dict[str, Any]:
        return {
            "id": id_,
            "travel_time_s": 6,
            "stops": [
                {
                    "floor": f"F{i}",
                    "node": f"{node}{i}",
                    "call": {"module": f"M{i}", "point": f"{p}_call"},
                    "in_position": {"module": f"M{i}", "point": f"{p}_here"},
                }
                for i in (0, 1)
            ],
        }

    return {
        "name": "Safety venue",
        "floors": [{"id": "F0"}, {"id": "F1", "level": 1}],
        "nodes": f0 + f1,
        "edges": edges,
        "charging_stations": [{"id": f"c{i}", "node": f"home{i}"} for i in (1, 2, 3)],
        # Robots sent anywhere else would be sent back to charge by the idle policy.
        "wait_points": [
            {"id": f"wp_{n}", "node": n} for n in ("hall", "west", "w_dock", "east", "up_w", "up_e")
        ],
        "areas": [
            {"id": "corr_a", "nodes": ["ca1", "ca2"], "passing_place": "west"},
            {"id": "corr_b", "nodes": ["cb1", "cb2"], "passing_place": "east"},
            {"id": "lift_a", "nodes": ["la0", "la1"], "passing_place": "hall"},
            {"id": "lift_b", "nodes": ["lb0", "lb1"], "passing_place": "east"},
        ],
        "doors": [
            {
                "id": f"D{i}",
                "node": f"door{i}",
                "open": {"module": f"M{i}", "point": f"d{i}_open"},
                "is_open": {"module": f"M{i}", "point": f"d{i}_is_open"},
                "open_time_s": 2,
            }
            for i in (0, 1)
        ],
        "elevators": [lift("lift_a", "la", "la"), lift("lift_b", "lb", "lb")],
        "modules": [{"id": f"M{i}", "points": points(str(i)), "port": 0} for i in (0, 1)],
        "robots": [
            {"name": f"R{i}", "token": f"robot-R{i}-safety-token", "start_node": f"home{i}"}
            for i in (1, 2, 3)
        ],
    }


@dataclass
class Fleet:
    server: RunningServer
    building: BuildingSimulator
    agents: dict[str, RobotAgent]
    checker: InvariantChecker
    seen: list[Message] = field(default_factory=list)
    states: dict[str, dict[str, Any]] = field(default_factory=dict)
    """The last robot_state of each robot."""
    changed: asyncio.Event = field(default_factory=asyncio.Event)
    robots: dict[str, dict[str, Any]] = field(default_factory=dict)
    """The site's robots (name -> its site entry)."""
    site_file: Path | None = None

    def new_agent(
        self, name: str, *, url: str | None = None, start_node: str | None = None
    ) -> RobotAgent:
        """A robot agent as the rig starts them (not started): ``url`` another way to the
        server (a LinkCutter), ``start_node`` where it stands (default: the site's)."""
        spec = self.robots[name]
        return rig_agent(
            url or self.server.url, spec, self.site_file, start_node or spec["start_node"]
        )

    def of(self, type_: str, **fields: Any) -> list[Message]:
        return [
            m
            for m in self.seen
            if m.type == type_ and all(m.payload.get(k) == v for k, v in fields.items())
        ]

    async def wait_for(self, predicate: Callable[[], Any], timeout: float = 30.0) -> None:
        async with asyncio.timeout(timeout):
            while not predicate():
                self.changed.clear()
                await asyncio.wait({asyncio.ensure_future(self.changed.wait())}, timeout=0.25)

    async def go(self, robot: str, node: str, timeout: float = 40.0) -> None:
        """A go_to task for ``robot`` (POST /api/tasks), waited until the robot ends it."""
        async with httpx.AsyncClient(base_url=self.server.url) as http:
            r = await http.post(
                "/api/tasks",
                json={"kind": "go_to", "params": {"node": node}, "robot": robot},
                headers={"Authorization": f"Bearer {self.server.admin_token}"},
            )
        assert r.status_code == 201, r.text
        task_id = r.json()["id"]
        await self.wait_for(lambda: self.of("task_ended", task_id=task_id), timeout)
        ended = self.of("task_ended", task_id=task_id)[0].payload
        assert ended["outcome"] == "done", f"{robot} to {node}: {ended}"


def one_door_site() -> dict[str, Any]:
    """The safety venue's ground floor only: west of door D0 (``west``, ``w_dock`` and the
    corridors) nothing leads to the hall and the chargers (home1..3) but through D0."""
    data = safety_site()
    gone = {"la0", "lb0", "door1"} | {n["id"] for n in data["nodes"] if n["floor"] == "F1"}
    data["floors"] = [f for f in data["floors"] if f["id"] == "F0"]
    data["nodes"] = [n for n in data["nodes"] if n["id"] not in gone]
    data["edges"] = [e for e in data["edges"] if not {e["a"], e["b"]} & gone]
    data["areas"] = [a for a in data["areas"] if not set(a["nodes"]) & gone]
    data["wait_points"] = [w for w in data["wait_points"] if w["node"] not in gone]
    data["doors"] = [d for d in data["doors"] if d["id"] == "D0"]
    data["elevators"] = []
    data["modules"] = [m for m in data["modules"] if m["id"] == "M0"]
    return data


def rig_agent(
    url: str, robot: dict[str, Any], site_file: Path | None, start_node: str, **extra: Any
) -> RobotAgent:
    """One robot of the rig: bare simulated base, real WebSocket link to ``url``; ``extra``
    goes to its AgentConfig (a touch screen: ``gui_port=0, auto_answer="yes"``)."""
    return RobotAgent(
        AgentConfig(
            name=robot["name"],
            server=url,
            token=robot["token"],
            can=None,
            time_scale=ROBOT_SCALE,
            start_node=start_node,
            speech_engine=None,
            state_period_s=0.2,
            site=site_file,
            idle_net=None,
            **extra,
        )
    )


WALK_STOPS = ["p_hall", "p_west", "p_east"]


def with_walk(site: dict[str, Any]) -> dict[str, Any]:
    """``site`` with the tour "walk": hall, then west and east (the points at those nodes)."""
    site["pois"] = [
        {"id": poi, "node": poi.removeprefix("p_"), "name": poi, "text": f"This is {poi}."}
        for poi in WALK_STOPS
    ]
    site["tours"] = [{"id": "walk", "name": "Walk", "points": WALK_STOPS}]
    return site


@contextlib.asynccontextmanager
async def guides(f: Fleet, names: list[str]) -> AsyncIterator[dict[str, RobotAgent]]:
    """The robots of a fleet started with ``external=``, each with its touch screen and a
    visitor who always wants more, once each is linked and has told its state."""
    agents: dict[str, RobotAgent] = {}
    try:
        for name in names:
            spec = f.robots[name]
            agent = rig_agent(
                f.server.url,
                spec,
                f.site_file,
                spec["start_node"],
                gui_port=0,
                auto_answer="yes",
            )
            await agent.start()
            agents[name] = f.agents[name] = agent
        hub = f.server.app.state.hub
        await f.wait_for(lambda: set(agents) <= set(hub.clients))
        await f.wait_for(lambda: all(f.states.get(n) for n in agents))
        yield agents
    finally:
        for agent in agents.values():
            await agent.stop()


@contextlib.asynccontextmanager
async def fleet(
    tmp_path: Path,
    robots: list[str],
    *,
    start: dict[str, str] | None = None,
    site: dict[str, Any] | None = None,
    external: frozenset[str] = frozenset(),
    **settings: Any,
) -> AsyncIterator[Fleet]:
    """``external``: robots of the site the test starts itself (``Fleet.new_agent``);
    ``settings``: server settings beyond the database and the site."""
    data = site if site is not None else safety_site()
    for robot in data["robots"]:
        if start and robot["name"] in start:
            robot["start_node"] = start[robot["name"]]
    data["robots"] = [r for r in data["robots"] if r["name"] in robots]
    building = BuildingSimulator(load_building(data), time_scale=BUILDING_SCALE, port_zero=True)
    async with building:
        for module in data["modules"]:
            module["port"] = building.ports[module["id"]]
        site_file = tmp_path / "site.yaml"
        site_file.write_text(yaml.safe_dump(data))
        checker = InvariantChecker.from_site(validate_site(data))
        config = Settings(
            db_url=f"sqlite+aiosqlite:///{tmp_path}/guidebot.db", site=site_file, **settings
        )
        async with running_server(config) as server, contextlib.AsyncExitStack() as stack:
            seen: list[Message] = []
            f = Fleet(server, building, {}, checker, seen, site_file=site_file)
            f.robots = {r["name"]: r for r in data["robots"]}

            def record(message: Message) -> None:
                if message.type == "robot_state":
                    f.states[str(message.payload.get("robot"))] = message.payload
                    f.changed.set()
                    return
                if message.type == "building_module_health":
                    return
                seen.append(message)
                if message.type == "area_granted":
                    # Published inside the handler of its cause (a release_area): this monitor
                    # sees it before the cause, so it is checked once the cause is delivered.
                    asyncio.get_running_loop().call_soon(checker.feed_message, message)
                else:
                    checker.feed_message(message)
                f.changed.set()

            server.app.state.hub.endpoint("test-monitor").subscribe("*", record, tap=True)
            await f.wait_for(lambda: server.app.state.building is not None, timeout=10)
            for r in data["robots"]:
                if r["name"] in external:
                    continue
                agent = rig_agent(server.url, r, site_file, r["start_node"])
                await stack.enter_async_context(agent)
                f.agents[r["name"]] = agent
            hub = server.app.state.hub
            await f.wait_for(lambda: set(f.agents) <= set(hub.clients))
            # The building's doors and cabins are known (first samples) before anyone moves.
            # Asked of the interface, not of its first door_closed / elevator_in_position: it
            # polls from the server's start on, and on a loaded machine some of those went
            # out before this monitor subscribed (then the rig waited for them for ever).
            building = server.app.state.building
            await f.wait_for(
                lambda: (
                    all(p.health.polls for p in building.pollers.values())
                    and all(keeper.is_open is not None for keeper in building.doors.values())
                )
            )
            yield f
