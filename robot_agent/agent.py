"""One robot agent: the on-board bus and every module on it, started and stopped in order.

Layers (GuideBot paper, section 4): hardware servers (RoboCAN master and its entities, or a
bare simulated base), control (navigation, speech, battery logic), executive (RG dispatch with
the net library, the main-task runner), interface (the link to the server, the touch screen).
``async with RobotAgent(config) as agent`` runs it; ``agent.bus`` is the on-board bus.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from fastapi import FastAPI

from guidebot.bus import Bus
from guidebot.payloads.robot import RobotState
from guidebot.service import Service
from robot_agent.battery import BatteryMonitor
from robot_agent.clock import Clock
from robot_agent.evacuation import Evacuation
from robot_agent.gui import OnboardScreen, ScreenServer, VisitorAnswer
from robot_agent.hardware import BareSimulation, Hardware, RoboCANHardware
from robot_agent.head import HeadWatchdog
from robot_agent.link import Link
from robot_agent.metrics import RobotMetrics
from robot_agent.navigation import Navigator
from robot_agent.net_sync import NetFollower
from robot_agent.reaction import ReactionTracker
from robot_agent.site_sync import SiteFollower
from robot_agent.speech import Speech
from robot_agent.state import StateReporter
from robot_agent.tasks import TaskRunner
from robot_agent.visitor_needs import VisitorNeeds

__all__ = ["AgentConfig", "RobotAgent", "hub_ws_url"]

log = logging.getLogger(__name__)


@dataclass
class AgentConfig:
    """Everything ``guidebot robot`` takes; defaults suit a simulated robot."""

    name: str
    server: str | None = None
    """Server URL (http://host:port or ws://host:port/ws); None: no link (standalone)."""
    token: str | None = None
    can: str | None = None
    """``virtual:R1`` or ``socketcan:can0``; None: no CAN, a bare simulated base."""
    simulate: bool = True
    time_scale: float = 1.0
    gui_port: int | None = None
    start_node: str | None = None
    max_speed: float = 0.7
    battery_low: float = 0.3
    battery_panic: float = 0.1
    battery_level: float | None = None
    """Initial level of the simulated battery (None: the simulator's default)."""
    bare_battery: bool = False
    """With ``can=None``: a simulated battery too (drain, charging; robot_agent/sim_base.py), on
    the robot's clock (``guidebot plan --virtual``). Without it a bare robot has no battery."""
    state_period_s: float = 1.0
    site: Path | None = None
    """Site file: tours and points of interest for the touch screen."""
    speech_engine: str | None = "auto"
    idle_net: str | None = "waiting"
    link_queue_size: int = 1000
    auto_answer: VisitorAnswer | None = None
    """Demo: a simulated visitor answers "continue the tour?" with this (None: nobody does)."""
    offline_requests: Literal["queue", "refuse"] = "queue"
    """Touch-screen requests while the link is down: kept and sent later, or refused."""


def hub_ws_url(server: str) -> str:
    """Accept http(s)://host:port or ws(s)://host:port/ws and return the hub's WebSocket URL."""
    url = server.rstrip("/")
    if url.startswith("http://"):
        url = "ws://" + url[len("http://") :]
    elif url.startswith("https://"):
        url = "wss://" + url[len("https://") :]
    elif not url.startswith(("ws://", "wss://")):
        raise ValueError(f"server URL {server!r}: expected http://host:port or ws://host:port/ws")
    return url if url.endswith("/ws") else url + "/ws"


@dataclass
class OnboardSite:
    """What the robot knows of the site: the touch screen's menu and the on-board map."""

    tours: list[dict[str, Any]]
    pois: list[dict[str, Any]]
    planner: Callable[[str, str], dict[str, Any]] | None
    floor_of: dict[str, str] = field(default_factory=dict)
    """Node -> floor: the robot reports its floor from the start."""
    position_of: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Node -> (x, y): the robot reports its start node's position before it first moves."""
    site: Any = None
    """The parsed site (guidebot.site.schema.Site): the touch screen's texts per language."""


def load_onboard_site(path: Path | None) -> OnboardSite:
    """Parse the site file (slow: call it in a thread)."""
    if path is None:
        return OnboardSite([], [], None, {})
    from guidebot.site.yamlio import load_site_file

    return onboard_site(load_site_file(path))


def onboard_site(site: Any) -> OnboardSite:
    """The on-board view of a ``Site``: menu entries and a planner over its graph."""
    from guidebot.site.graph import SiteGraph

    graph = SiteGraph(site)

    def planner(start: str, goal: str) -> dict[str, Any]:
        result = graph.shortest_path(start, goal)
        return {
            "nodes": result.nodes,
            "length_m": result.length_m,
            "steps": [s.as_dict() for s in result.steps],
        }

    tours = [{"id": t.id, "name": t.name, "points": t.points} for t in site.tours]
    pois = [{"id": p.id, "name": p.name, "node": p.node} for p in site.pois]
    return OnboardSite(
        tours,
        pois,
        planner,
        {n.id: n.floor for n in site.nodes},
        {n.id: (n.x, n.y) for n in site.nodes},
        site,
    )


class RobotAgent(Service):
    def __init__(self, config: AgentConfig) -> None:
        super().__init__()
        self.config = config
        self.clock = Clock(config.time_scale)
        self.bus = Bus()
        self.hardware: Hardware | None = None
        self.navigator: Navigator | None = None
        self.speech: Speech | None = None
        self.head: HeadWatchdog | None = None
        self.battery: BatteryMonitor | None = None
        self.tasks: TaskRunner | None = None
        self.needs: VisitorNeeds | None = None
        self.evacuation: Evacuation | None = None
        self.state: StateReporter | None = None
        self.dispatch: Any = None
        self.hub: Any = None
        self.link: Link | None = None
        self.screen: OnboardScreen | None = None
        self.site_follower: SiteFollower | None = None
        self.net_follower: NetFollower | None = None
        self.screen_server: ScreenServer | None = None
        self.reaction: ReactionTracker | None = None
        self.metrics: RobotMetrics | None = None

    async def on_start(self) -> None:
        """Every module in order; each is stopped, newest first, on stop or a failed start."""
        c = self.config
        name = c.name
        bus = self.bus

        # The net library first: parsing it takes a while and must not stall the hardware's
        # watchdogs once RoboCAN runs (so it is parsed in a thread, before).
        self.dispatch = await self._make_dispatch()
        onboard_site = await asyncio.to_thread(load_onboard_site, c.site)

        # Hardware servers.
        hw_ep = bus.endpoint("robocan" if c.can else "base")
        if c.can:
            self.hardware = RoboCANHardware(
                hw_ep,
                self.clock,
                can=c.can,
                simulate=c.simulate,
                robot=name,
                battery_low=c.battery_low,
                battery_panic=c.battery_panic,
                battery_level=c.battery_level,
            )
        else:
            level = 1.0 if c.battery_level is None else c.battery_level
            self.hardware = BareSimulation(
                hw_ep, self.clock, battery=level if c.bare_battery else None
            )

        # Control modules.
        self.navigator = Navigator(
            bus.endpoint("navigation"),
            self.clock,
            name,
            start_node=c.start_node,
            max_speed=c.max_speed,
            planner=onboard_site.planner,
            floor_of=onboard_site.floor_of,
            position_of=onboard_site.position_of,
        )
        await self.enter(self.navigator)
        # Only RoboCAN's BellBot set has a head; a bare base's gestures are always skipped.
        self.head = HeadWatchdog(bus.endpoint("head_watchdog"), self.clock, fitted=bool(c.can))
        await self.enter(self.head)
        self.speech = Speech(bus.endpoint("speech"), self.clock, engine=c.speech_engine)
        await self.enter(self.speech)
        self.battery = BatteryMonitor(
            bus.endpoint("battery"),
            name,
            low=c.battery_low,
            panic=c.battery_panic,
            alarms=not c.can,  # RoboCAN's battery entity publishes the alarms itself
        )
        await self.enter(self.battery)

        # Executive: RG dispatch and the main-task runner.
        nets = None
        if self.dispatch is not None:
            self.dispatch.open()
            self.on_cleanup(self.dispatch.close)
            dispatch = self.dispatch

            def nets() -> list[str]:
                return sorted({i["net"] for i in dispatch.running()})

        navigator, battery = self.navigator, self.battery
        self.reaction = ReactionTracker(bus.endpoint("reaction"), name)
        await self.enter(self.reaction)  # before the task runner: see robot_agent/reaction.py
        self.tasks = TaskRunner(
            bus.endpoint("tasks"),
            name,
            waiting_net=None if self.dispatch is not None else c.idle_net,
            on_cancel=navigator.cancel_goal,
            on_start=battery.undock,
        )
        await self.enter(self.tasks)
        self.needs = VisitorNeeds(bus.endpoint("needs"), self.tasks, navigator, self.speech)
        await self.enter(self.needs)
        self.evacuation = Evacuation(bus.endpoint("evacuation"), name, navigator, self.tasks)
        await self.enter(self.evacuation)
        self.state = StateReporter(
            bus.endpoint("state"),
            name,
            navigator,
            battery,
            self.tasks,
            nets=nets,
            period_s=c.state_period_s,
        )

        # Interface: the link to the server, the touch screen.
        if c.server:
            await self._start_link()
        await self.enter(self.state)
        if c.gui_port is not None:
            tours, pois = onboard_site.tours, onboard_site.pois
            self.screen = OnboardScreen(
                bus.endpoint("screen"),
                self.clock,
                name,
                tours=tours,
                pois=pois,
                state=self.state.snapshot_view,
                auto_answer=c.auto_answer,
                site=onboard_site.site,
                site_file=c.site,
                link_up=self._link_up if c.server else None,
                offline_requests=c.offline_requests,
            )
            await self.enter(self.screen)
            self.metrics = RobotMetrics(bus.endpoint("metrics"), name, self._masters)
            await self.enter(self.metrics)
            self.screen_server = ScreenServer(
                self.screen,
                port=c.gui_port,
                metrics=self.metrics.render,
                extra=self._sim_routes(),
            )
            await self.enter(self.screen_server)
        # Hardware last: its watchdogs run from here on, with every module ready to listen.
        await self.enter(self.hardware)
        log.info(
            "robot %s up: hardware=%s link=%s screen=%s",
            name,
            type(self.hardware).__name__,
            c.server or "none",
            self.screen_server.url if self.screen_server else "none",
        )

    def _link_up(self) -> bool:
        return self.link is not None and self.link.upstream.connected.is_set()

    def _masters(self) -> list[Any]:
        """The RoboCAN masters (none without CAN or before the hardware started)."""
        stack = getattr(self.hardware, "stack", None)
        return list(getattr(stack, "masters", ()))

    def _sim_routes(self) -> Callable[[FastAPI], None] | None:
        """Fault injection on the screen port, for simulated RoboCAN modules only."""
        hardware = self.hardware
        if not (self.config.simulate and isinstance(hardware, RoboCANHardware)):
            return None
        from robot_agent.sim_control import add_sim_routes

        endpoint = self.bus.endpoint("sim_control")

        def modules() -> list[int]:
            stack = hardware.stack
            return list(stack.simulator.layout) if stack and stack.simulator else []

        return lambda app: add_sim_routes(app, endpoint, modules)

    async def _make_dispatch(self) -> Any:
        try:
            from petri_nets.clock import AsyncioClock
            from petri_nets.dispatch import Dispatch
            from petri_nets.library import NetLibrary
        except ImportError as exc:  # RoboGraph missing: tasks cannot run, say so loudly
            log.error("RoboGraph is not available (%s): main tasks will fail", exc)
            return None
        library = await asyncio.to_thread(NetLibrary, watch=False)
        for problem in library.problems():
            log.warning("net library: %s", problem)
        return Dispatch(
            self.bus.endpoint("dispatch"),
            library,
            AsyncioClock(scale=self.config.time_scale),
            idle_net=self.config.idle_net,
        )

    async def _start_link(self) -> None:
        from guidebot.client import HubClient

        c = self.config
        if not c.token:
            raise ValueError("a server URL needs a token (--token)")
        self.hub = HubClient(
            hub_ws_url(c.server or ""),
            c.token,
            connect_timeout=None,
            queue_size=c.link_queue_size,
        )
        state = self.state
        assert state is not None
        follower = SiteFollower(
            self.bus.endpoint("site"), c.name, self._use_site, prepare=onboard_site
        )
        await self.enter(follower)
        self.site_follower = follower
        nets = None
        if self.dispatch is not None:
            nets = NetFollower(self.bus.endpoint("nets"), c.name, self.dispatch.library)
            await self.enter(nets)
        self.net_follower = nets
        navigator = self.navigator
        assert navigator is not None

        def on_connect() -> None:
            state.publish_now()  # first: the server takes back the areas it holds
            navigator.resync()
            follower.announce()
            if nets is not None:
                nets.announce()

        self.link = Link(
            self.bus.endpoint("link"),
            self.hub,
            c.name,
            on_connect=on_connect,
            on_disconnect=navigator.link_lost,
        )
        await self.enter(self.link)
        await self.hub.start()
        self.on_cleanup(self._leave)

    async def _leave(self) -> None:
        """A clean exit says so before the link closes: a last robot_state with mode
        "offline" (the server then raises no "robot lost" alert, docs/protocol.md)."""
        hub, state = self.hub, self.state
        assert hub is not None and state is not None
        if hub.connected.is_set():
            with contextlib.suppress(Exception):  # the link may drop meanwhile: a lost robot
                hub.publish(RobotState(**{**state.snapshot(), "mode": "offline"}))
        await hub.close()

    def _use_site(self, view: OnboardSite) -> None:
        """A new live site (read in a thread): the fallback planner and the screen's menu
        follow it."""
        if self.navigator is not None:
            self.navigator.planner = view.planner
            self.navigator.plan_on_board = True  # the server's live version: plan on board
        if self.screen is not None:
            self.screen.tours, self.screen.pois = view.tours, view.pois
