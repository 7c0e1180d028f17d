"""Alerts against a real server: a robot agent whose link drops and comes back, a robot that
leaves cleanly, a Modbus module of building_sim going offline and back. Each alert resolves
itself when its cause is gone; a clean exit raises none (docs/console.md, "Alerts")."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from backend.settings import Settings
from backend.testing import RunningServer, running_server
from building_sim.simulator import BuildingSimulator
from guidebot.messages import Message
from guidebot.site.building_config import BuildingConfig
from guidebot.site.schema import Site
from guidebot.testing import wait_on, wait_until
from robot_agent.agent import AgentConfig, RobotAgent

pytestmark = pytest.mark.timeout(90)

TOKEN = "robot-R1-demo-token"
DEMO_SITE = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"


class Watch:
    """Every alert message and robot link event on the server's hub, with a wake-up event."""

    def __init__(self, server: RunningServer) -> None:
        self.server = server
        self.seen: list[Message] = []
        self.changed = asyncio.Event()
        server.app.state.hub.endpoint("test-watch").subscribe("*", self._record, tap=True)

    def _record(self, message: Message) -> None:
        if message.type.startswith(("alert_", "robot_", "building_module_health")):
            self.seen.append(message)
            self.changed.set()

    def of(self, type_: str, **payload: Any) -> list[Message]:
        return [
            m
            for m in self.seen
            if m.type == type_ and all(m.payload.get(k) == v for k, v in payload.items())
        ]

    async def wait(self, predicate: Callable[[], Any], timeout: float = 30.0) -> None:
        try:
            await wait_on(self.changed, predicate, timeout)
        except TimeoutError:
            seen = [(m.type, m.payload.get("kind"), m.payload.get("subject")) for m in self.seen]
            raise AssertionError(f"not reached within {timeout:g} s; seen {seen}") from None

    async def alerts(self) -> list[dict[str, Any]]:
        headers = {"Authorization": f"Bearer {self.server.admin_token}"}
        async with httpx.AsyncClient(base_url=self.server.url) as http:
            r = await http.get("/api/alerts?include_acked=true", headers=headers)
            r.raise_for_status()
            return list(r.json())

    async def post(self, path: str) -> dict[str, Any]:
        headers = {"Authorization": f"Bearer {self.server.admin_token}"}
        async with httpx.AsyncClient(base_url=self.server.url) as http:
            r = await http.post(path, headers=headers)
            r.raise_for_status()
            return dict(r.json())


def robot(server_url: str, demo_site_file: Path) -> RobotAgent:
    return RobotAgent(
        AgentConfig(
            name="R1",
            server=server_url,
            token=TOKEN,
            simulate=True,
            time_scale=20.0,
            start_node="charge_a",
            speech_engine=None,
            state_period_s=0.2,
            site=demo_site_file,
        )
    )


async def test_a_robot_back_online_resolves_its_alert_and_a_clean_exit_raises_none(
    tmp_path: Path, helpers: Any
) -> None:
    settings = Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/g.db", site=DEMO_SITE, building_enabled=False
    )
    async with running_server(settings) as server:
        watch = Watch(server)
        cutter = helpers.LinkCutter(server.port)
        await cutter.start()
        try:
            agent = robot(f"http://127.0.0.1:{cutter.port}", DEMO_SITE)
            async with agent:
                await watch.wait(lambda: watch.of("robot_connected", robot="R1"))
                await cutter.cut()  # the robot's Wi-Fi is gone
                await watch.wait(lambda: watch.of("alert_raised", kind="robot_lost"))
                [lost] = [a for a in await watch.alerts() if a["kind"] == "robot_lost"]
                assert lost["subject"] == "R1" and lost["resolved_at"] is None
                acked = await watch.post(f"/api/alerts/{lost['id']}/ack")
                assert acked["acked_by"] == "admin"
                await cutter.restore()
                await watch.wait(lambda: watch.of("alert_resolved", id=lost["id"]))
                [back] = [a for a in await watch.alerts() if a["id"] == lost["id"]]
                assert back["resolution"] == "robot R1 is back online"
                assert back["acked_by"] == "admin" and back["count"] == 1
                await watch.wait(lambda: len(watch.of("robot_connected", robot="R1")) >= 2)
            # A clean exit: the robot says it is leaving, its link closes, no alert.
            await watch.wait(lambda: len(watch.of("robot_disconnected", robot="R1")) >= 2)
            assert watch.of("robot_state", robot="R1", mode="offline")
            [after] = [a for a in await watch.alerts() if a["kind"] == "robot_lost"]
            assert after["resolved_at"] is not None and after["count"] == 1
            assert len(watch.of("alert_raised", kind="robot_lost")) == 1
        finally:
            await cutter.stop()


@contextlib.asynccontextmanager
async def building_server(
    tmp_path: Path, demo_site: Site
) -> AsyncIterator[tuple[RunningServer, BuildingSimulator]]:
    """The demo site's building served by building_sim, polled by the server."""
    config = BuildingConfig(
        modules=demo_site.modules,
        doors=demo_site.doors,
        elevators=demo_site.elevators,
        buttons=demo_site.buttons,
    )
    async with BuildingSimulator(config, port_zero=True) as sim:
        data = demo_site.model_dump(mode="json")
        for module in data["modules"]:
            module["port"] = sim.ports[module["id"]]
        site_file = tmp_path / "site.yaml"
        site_file.write_text(yaml.safe_dump(data))
        settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/g.db", site=site_file)
        async with running_server(settings) as server:
            yield server, sim


async def test_an_acknowledged_module_alert_stays_so_and_resolves_when_it_is_back(
    tmp_path: Path, demo_site: Site
) -> None:
    async with building_server(tmp_path, demo_site) as (server, sim):
        watch = Watch(server)
        poller = server.app.state.building.pollers["otb_first"]
        await wait_until(lambda: poller.health.online, timeout=30)
        await sim.set_fault("otb_first", "offline")
        await watch.wait(lambda: watch.of("alert_raised", kind="module_offline"))
        [down] = [a for a in await watch.alerts() if a["kind"] == "module_offline"]
        assert down["subject"] == "otb_first"
        await watch.post(f"/api/alerts/{down['id']}/ack")
        # Still offline, reported again (health every few seconds): it stays acknowledged.
        reports = len(watch.of("building_module_health", module="otb_first", online=False))
        await watch.wait(
            lambda: (
                len(watch.of("building_module_health", module="otb_first", online=False)) > reports
            )
        )
        async with httpx.AsyncClient(base_url=server.url) as http:
            headers = {"Authorization": f"Bearer {server.admin_token}"}
            assert (await http.get("/api/alerts", headers=headers)).json() == []
        [still] = [a for a in await watch.alerts() if a["id"] == down["id"]]
        assert still["acked_by"] == "admin" and still["resolved_at"] is None
        assert len(watch.of("alert_raised", kind="module_offline")) == 1
        await sim.set_fault("otb_first", "none")
        await watch.wait(lambda: watch.of("alert_resolved", id=down["id"]))
        [up] = [a for a in await watch.alerts() if a["id"] == down["id"]]
        assert up["resolution"] == "Modbus module otb_first is online"
        assert not [a for a in await watch.alerts() if a["resolved_at"] is None]


async def test_a_clean_shutdown_leaves_no_alert_for_the_next_start(
    tmp_path: Path, demo_site: Site
) -> None:
    """The demo's Ctrl-C: the robot stops (it says so), the building simulator stops while the
    server still polls it (true then: module_offline), the server stops. The next start shows
    no open alert: no robot was lost, and what the last life saw is resolved."""
    async with building_server(tmp_path, demo_site) as (server, sim):
        watch = Watch(server)
        poller = server.app.state.building.pollers["otb_first"]
        await wait_until(lambda: poller.health.online, timeout=30)
        async with robot(server.url, DEMO_SITE):
            await watch.wait(lambda: watch.of("robot_state", robot="R1"))
        await watch.wait(lambda: watch.of("robot_disconnected", robot="R1"))
        await sim.stop()
        await watch.wait(lambda: len(watch.of("alert_raised", kind="module_offline")) == 2)
        settings = server.app.state.settings
    assert not [m for m in watch.seen if m.payload.get("kind") == "robot_lost"]
    async with running_server(settings.model_copy(update={"building_enabled": False})) as again:
        watch = Watch(again)
        assert await watch.alerts() and not [
            a for a in await watch.alerts() if a["resolved_at"] is None
        ]
        assert {a["resolution"] for a in await watch.alerts()} == {
            "server restarted: raised again if its cause is still there"
        }
