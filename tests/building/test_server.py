"""The BuildingInterface inside the real server: a button press in building_sim becomes a task
(the paper's T1-T4) and the button's LED is lit through set_output."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import yaml

from backend.building.component import _building_part
from backend.settings import Settings
from backend.testing import RunningServer, running_server
from building_sim.simulator import BuildingSimulator
from guidebot.messages import Message
from guidebot.site.building_config import load_building
from guidebot.site.yamlio import load_site_text
from guidebot.testing import Recorder, wait_until

DEMO_SITE = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"


@contextlib.asynccontextmanager
async def demo_building(
    tmp_path: Path,
) -> AsyncIterator[tuple[dict[str, Any], BuildingSimulator, RunningServer]]:
    """The demo museum's modules simulated, and a server running the demo site with them:
    (the site's data, the simulator, the server)."""
    site = yaml.safe_load(DEMO_SITE.read_text(encoding="utf-8"))
    async with BuildingSimulator(load_building(site), time_scale=20, port_zero=True) as sim:
        for module in site["modules"]:
            module["port"] = sim.ports[module["id"]]
        site_file = tmp_path / "site.yaml"
        site_file.write_text(yaml.safe_dump(site), encoding="utf-8")
        settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", site=site_file)
        async with running_server(settings) as server:
            yield site, sim, server


async def test_button_press_requests_its_task_and_lights_its_led(tmp_path: Path) -> None:
    async with demo_building(tmp_path) as (_site, sim, server):
        building = server.app.state.building
        assert building is not None
        recorder = Recorder(server.app.state.hub.endpoint("test"), "task_event", "building_*")
        await wait_until(lambda: all(p.health.polls > 0 for p in building.pollers.values()))

        sim.press("button_entrance", ms=600)

        changed = await recorder.wait("building_input_changed", point="button_entrance")
        assert changed.payload["node"] == "entrance"
        assert changed.payload["floor"] is not None
        event: Message = await recorder.wait("task_event")
        assert event.payload["state"] == "queued"
        led = {"module": "otb_ground", "point": "led_entrance"}
        await wait_until(lambda: sim.read_point(**led) == 1)
        # ... and the interface has read the LED back.
        await wait_until(lambda: building.values.get(("otb_ground", "led_entrance")) == 1)
        headers = {"Authorization": f"Bearer {server.admin_token}"}
        async with httpx.AsyncClient(base_url=server.url, headers=headers) as http:
            state = (await http.get("/api/building")).json()
            assert (await http.get("/api/building")).status_code == 200
            assert (
                await http.get("/api/building", headers={"Authorization": ""})
            ).status_code == 401
        health = {h["module"]: h for h in state["modules"]}
        assert health["otb_ground"]["online"] is True
        assert health["otb_ground"]["rtt_ms"] is not None
        values = {(p["module"], p["point"]): p["value"] for p in state["points"]}
        assert values[("otb_ground", "led_entrance")] == 1


async def test_site_change_restarts_the_interface_with_the_new_modules(tmp_path: Path) -> None:
    async with demo_building(tmp_path) as (site, _sim, server):
        state = server.app.state
        old = state.building
        assert old.pollers["otb_ground"].period_s == 0.2
        site["modules"][0]["sampling_period_ms"] = 100
        await state.sites.replace(site)
        await wait_until(lambda: state.building is not None and state.building is not old)
        new = state.building
        assert new.pollers["otb_ground"].period_s == 0.1
        await wait_until(lambda: new.pollers["otb_ground"].health.polls > 0)
        assert not any(p.running for p in old.pollers.values())  # the old one stopped


async def test_a_site_edit_outside_the_building_leaves_the_interface_running(
    tmp_path: Path,
) -> None:
    """Moving a node must not reconnect every module nor forget the doors held for robots."""
    async with demo_building(tmp_path) as (site, _sim, server):
        state = server.app.state
        old = state.building
        await wait_until(lambda: all(p.health.polls > 0 for p in old.pollers.values()))
        robot = state.hub.endpoint("R1")
        reply = await robot.request("open_door", {"door": "door_gallery"}, timeout=10)
        assert reply.type == "door_opened"
        assert "R1" in old.doors["door_gallery"].holders

        site["nodes"][0]["x"] += 1.0
        await state.sites.replace(site)
        await asyncio.sleep(1.0)  # a restart starts at once (see the test above)

        assert state.building is old
        assert all(p.running for p in old.pollers.values())
        assert "R1" in old.doors["door_gallery"].holders
        polls = old.pollers["otb_ground"].health.polls
        await wait_until(lambda: old.pollers["otb_ground"].health.polls > polls)


def test_the_building_part_names_the_floors_of_the_nodes_its_points_name() -> None:
    """A new floor for a node that a point names (a call button's) rebuilds the interface; a
    new floor for any other node does not."""
    site = load_site_text(DEMO_SITE.read_text(encoding="utf-8"))
    floors = {node.id: node.floor for node in site.nodes}
    named = next(p.node for m in site.modules for p in m.points if p.node is not None)
    other = next(n.id for n in site.nodes if n.id != named)
    part = _building_part(site, floors)
    assert part[1][named] == floors[named]
    assert _building_part(site, {**floors, other: "elsewhere"}) == part
    assert _building_part(site, {**floors, named: "elsewhere"}) != part


async def test_a_call_pressed_again_is_logged_once(tmp_path: Path) -> None:
    """Robots press a lift's call again while they wait and while they drive in or out (to
    keep the door open): the event log keeps the call that is news, not a row per press (a
    press where the cabin already stood open also started a bogus elevator wait in the
    reports, ended only by the cabin's next arrival)."""
    async with demo_building(tmp_path) as (_site, _sim, server):
        hub = server.app.state.hub
        recorder = Recorder(hub.endpoint("test"), "elevator_state", "elevator_in_position")
        robot = hub.endpoint("R1")
        building = server.app.state.building
        await wait_until(lambda: all(p.health.polls > 0 for p in building.pollers.values()))
        robot.publish("call_elevator", {"elevator": "lift", "floor": "F1"})
        await recorder.wait("elevator_state", lambda m: "F1" in m.payload["calls"])
        robot.publish("call_elevator", {"elevator": "lift", "floor": "F1"})  # waiting
        await recorder.wait("elevator_in_position", floor="F1")
        await recorder.wait("elevator_state", floor="F1", door_open=True)
        robot.publish("call_elevator", {"elevator": "lift", "floor": "F1"})  # keep it open
        robot.publish("call_elevator", {"elevator": "lift", "floor": "F0"})  # news: logged
        await recorder.wait("elevator_state", lambda m: "F0" in m.payload["calls"])
        calls = await server.app.state.store.events(kind="call_elevator")
        assert [(e["source"], e["data"]["floor"]) for e in calls] == [("R1", "F1"), ("R1", "F0")]
