"""The fire alarm over real Modbus/TCP: the demo museum's alarm input raised at the building
simulator's control port holds the real server (issue 35, docs/emergency.md)."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from backend.settings import Settings
from backend.testing import RunningServer, running_server
from building_sim.control import serve_control
from building_sim.simulator import BuildingSimulator
from guidebot.site.building import IORef
from guidebot.site.building_config import load_building
from guidebot.testing import Recorder, wait_until
from tests.server.helpers import RobotStub

from .test_server import DEMO_SITE, demo_building

ALARM = "/points/otb_ground/fire_alarm"


@contextlib.asynccontextmanager
async def alarm_rig(
    tmp_path: Path,
) -> AsyncIterator[tuple[BuildingSimulator, RunningServer, httpx.AsyncClient, httpx.AsyncClient]]:
    """The demo building and server, the simulator's control port, a staff REST client."""
    async with demo_building(tmp_path) as (_site, sim, server):
        async with serving(server) as http, serve_control(sim) as url:
            async with httpx.AsyncClient(base_url=url) as control:
                yield sim, server, control, http


@contextlib.asynccontextmanager
async def serving(server: RunningServer) -> AsyncIterator[httpx.AsyncClient]:
    """Once every module has been polled: a staff REST client of the server."""
    building = server.app.state.building
    await wait_until(lambda: all(p.health.polls > 0 for p in building.pollers.values()))
    headers = {"Authorization": f"Bearer {server.admin_token}"}
    async with httpx.AsyncClient(base_url=server.url, headers=headers) as http:
        yield http


async def _state(http: httpx.AsyncClient) -> dict[str, Any]:
    response = await http.get("/api/emergency")
    assert response.status_code == 200, response.text
    return response.json()


async def test_alarm_input_holds_the_fleet_and_resume_takes_two_steps(tmp_path: Path) -> None:
    async with alarm_rig(tmp_path) as (_sim, server, control, http):
        hub = server.app.state.hub
        recorder = Recorder(hub.endpoint("test"), "emergency_changed", "task_event")
        robot = RobotStub(hub, "R1", "gb1")  # east of the corridor, an escape route
        robot.state()
        created = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}})
        assert created.status_code == 201, created.text
        task_id = created.json()["id"]
        await robot.wait_for("task_assigned")
        robot.start(task_id)
        robot.state("busy")
        await recorder.wait("task_event", task_id=task_id, state="running")

        # The building's alarm relay closes: the input is read over Modbus/TCP.
        assert (await control.post(ALARM, json={"value": 1})).status_code == 200
        changed = await recorder.wait("emergency_changed", state="alarm")
        assert changed.payload["declared_by"] == "input:fire_main"
        assert changed.payload["words"]["es"].startswith("Alarma de incendio")
        # The robot's tour is cut off (back in the queue, held) and it is sent to safety by
        # the one-way back gallery, not through the corridor.
        order = await robot.wait_for("evacuate")
        assert order.payload["path"] == ["gb1", "gb2", "ga2"]
        assert order.payload["safe_spot"] == "ga2"
        await recorder.wait("task_event", task_id=task_id, state="queued")
        state = await _state(http)
        assert state["state"] == "alarm" and state["cut_off_tasks"] == [task_id]
        assert state["alarms"] == [
            {"id": "fire_main", "module": "otb_ground", "point": "fire_alarm", "reads_alarm": True}
        ]
        # New requests: 503 with the reason, in the visitor's language.
        refused = await http.post(
            "/api/tasks", json={"kind": "tour", "params": {"tour": "ground", "lang": "es"}}
        )
        assert refused.status_code == 503
        assert refused.json()["reason"] == "emergency"
        assert refused.json()["detail"].startswith("Alarma de incendio")
        # No area grant but on a robot's way to safety: R1's way avoids the corridor...
        robot.endpoint.publish("request_area", {"robot": "R1", "area": "corridor"})
        refusal = await robot.wait_for("error")
        assert "fire alarm: area corridor is closed" in refusal.payload["reason"]
        # ... R2, connecting in the corridor during the alarm, is held and sent out of it,
        # through the area it stands in.
        other = RobotStub(hub, "R2", "corridor_e")
        other.state()
        out = await other.wait_for("evacuate")
        assert out.payload["path"] == ["corridor_e", "gb1", "gb2", "ga2"]
        other.endpoint.publish("request_area", {"robot": "R2", "area": "corridor"})
        await other.wait_for("area_granted")
        # The same refusal for a visitor at a robot's screen (task_request on the hub).
        robot.endpoint.publish(
            "task_request", {"kind": "tour", "params": {"tour": "ground", "lang": "es"}}
        )
        hub_refusal = await robot.wait_for("error", count=2)
        assert hub_refusal.payload["code"] == "task_refused"
        assert hub_refusal.payload["reason"].startswith("Alarma de incendio")
        # No door opened for anyone in the zone.
        robot.endpoint.publish("open_door", {"door": "door_gallery"})
        failed = await robot.wait_for("command_failed")
        assert "fire alarm" in failed.payload["reason"]
        # The robot reports its way to safety; it is in the state and the event log.
        robot.endpoint.publish("evacuation_state", {"state": "safe", "node": "ga2"})
        await wait_until(lambda: server.app.state.emergency.evacuation["R1"]["state"] == "safe")

        # Step one missing: the input still reads alarm. Refused, saying why.
        early = await http.post("/api/emergency/resume")
        assert early.status_code == 409
        assert "fire_main (otb_ground/fire_alarm) still reads alarm" in early.json()["detail"]

        # The building's alarm is reset: service waits for a person.
        assert (await control.post(ALARM, json={"value": 0})).status_code == 200
        await recorder.wait("emergency_changed", state="input_clear")
        robot.node = "ga2"
        robot.task_id = None
        robot.state()
        assert (await robot_held_still(server, "R1")) is True

        resumed = await http.post("/api/emergency/resume")
        assert resumed.status_code == 200, resumed.text
        assert resumed.json()["resumed_tasks"] == [task_id]
        await recorder.wait("emergency_changed", state="normal")
        # The held queue runs: the cut-off tour goes to the robot again.
        await robot.wait_for("task_assigned", count=2)
        again = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}})
        assert again.status_code == 201
        events = (await http.get("/api/events", params={"limit": 500})).json()
        kinds = {e["kind"] for e in (events["events"] if isinstance(events, dict) else events)}
        assert {"emergency_declared", "robot_evacuation", "emergency_input_clear"} <= kinds
        assert "emergency_resumed" in kinds


async def waiting_for_the_jammed_gallery_door(
    sim: BuildingSimulator, server: RunningServer
) -> RobotStub:
    """R1 at the hall, its open_door waiting for door_gallery (jammed: it cannot open, however
    slow the machine), the door's coil set."""
    robot = RobotStub(server.app.state.hub, "R1", "hall")
    robot.state()
    sim.jam_door("door_gallery")
    robot.endpoint.publish("open_door", {"door": "door_gallery"})
    await wait_until(lambda: sim.read_point("otb_ground", "door_hall_open") == 1)
    return robot


async def test_an_evacuation_raises_no_door_trouble_for_a_door_a_robot_was_waiting_for(
    tmp_path: Path,
) -> None:
    """A robot's open_door still waiting for door_gallery (jammed: it cannot open first) when
    the fire alarm comes: the alarm drops the door's holders, and the request is withdrawn, not
    timed out into a trouble closure and a building_command_failed alert mid-evacuation."""
    async with alarm_rig(tmp_path) as (sim, server, control, http):
        hub, building = server.app.state.hub, server.app.state.building
        failures = Recorder(hub.endpoint("test"), "command_failed", tap=True)
        robot = await waiting_for_the_jammed_gallery_door(sim, server)
        assert (await control.post(ALARM, json={"value": 1})).status_code == 200
        await robot.wait_for("evacuate")
        await wait_until(lambda: not building.doors["door_gallery"].holders)
        await wait_until(lambda: not building._commands)  # the open_door's handler is done
        assert failures.messages == []
        assert sim.read_point("otb_ground", "door_hall_open") == 0
        assert [c.id for c in server.app.state.closures.closures.values()] == []
        alerts = (await http.get("/api/alerts")).json()
        assert [a["kind"] for a in alerts if a["kind"] != "fire_alarm"] == []


async def test_a_robot_outside_the_zone_is_told_at_once_that_the_alarm_holds_its_door(
    tmp_path: Path,
) -> None:
    """A floor alarm (F1) while R2, on the ground floor, waits for door_upstairs (F1, jammed:
    it cannot open first) and R1, upstairs, waits for it too. The alarm drops the door's
    holders: R1, evacuating, wants no door any more (withdrawn, no answer); R2 still wants it
    and is told at once that the alarm holds it (it got no answer and waited its whole
    wait_timeout_s). A refusal, not trouble: no trouble closure."""
    async with alarm_rig(tmp_path) as (sim, server, _control, http):
        hub = server.app.state.hub
        building = server.app.state.building
        inside, outside = RobotStub(hub, "R1", "gc1"), RobotStub(hub, "R2", "hall")
        inside.state()
        outside.state()
        sim.jam_door("door_upstairs")
        for robot in (inside, outside):
            robot.endpoint.publish("open_door", {"door": "door_upstairs"})
        await wait_until(lambda: set(building.doors["door_upstairs"].holders) == {"R1", "R2"})
        declared = await http.post(
            "/api/emergency/declare", json={"zone": {"floors": ["F1"]}, "reason": "drill"}
        )
        assert declared.status_code == 200, declared.text
        await inside.wait_for("evacuate")
        # The alarm's words, not the jammed door's time-out (the first answer R2 gets; no
        # wall-clock bound: a loaded machine may take seconds, and "at once" is the order).
        failed = await outside.wait_for("command_failed", timeout=60.0)
        assert failed.payload["command"] == "open_door"
        assert failed.payload["target"] == "door_upstairs"
        assert failed.payload["reason"].startswith("fire alarm: no door opened"), failed.payload
        assert failed.payload["refused"] is True  # a rule, not the door: no alert
        # R2 asks again (as a robot does every door_retry_s): refused at once, again no alert.
        outside.endpoint.publish("open_door", {"door": "door_upstairs"})
        again = await outside.wait_for("command_failed", count=2, timeout=60.0)
        assert again.payload["refused"] is True and "fire alarm" in again.payload["reason"]
        await wait_until(lambda: not building._commands)  # the open_doors' handlers are done
        assert inside.of_type("command_failed") == []
        assert outside.of_type("evacuate") == []
        assert sim.read_point("otb_first", "door_f1_open") == 0
        assert [c.id for c in server.app.state.closures.closures.values()] == []
        raised = {(a.kind, a.subject) for a in server.app.state.alerts.active()}
        assert not any(kind == "building_command_failed" for kind, _ in raised), raised


async def test_staff_closing_a_door_withdraws_the_open_doors_waiting_for_it(
    tmp_path: Path,
) -> None:
    """Staff close door_gallery (close_door) while R1's open_door still waits for it (jammed):
    every holder is dropped and R1's request withdrawn, as when a robot lets go; its time-out
    used to be published as a door failure (command_failed, a trouble closure and a
    building_command_failed alert) for a door staff had closed on purpose."""
    async with alarm_rig(tmp_path) as (sim, server, _control, http):
        hub, building = server.app.state.hub, server.app.state.building
        failures = Recorder(hub.endpoint("test"), "command_failed", tap=True)
        await waiting_for_the_jammed_gallery_door(sim, server)
        staff = hub.endpoint("staff")
        closed = await staff.request("close_door", {"door": "door_gallery"}, timeout=10)
        assert closed.type == "door_closed", closed.payload
        await wait_until(lambda: not building._commands)  # the open_door's handler is done
        assert failures.messages == []
        assert building.doors["door_gallery"].holders == {}
        assert sim.read_point("otb_ground", "door_hall_open") == 0
        assert [c.id for c in server.app.state.closures.closures.values()] == []
        alerts = (await http.get("/api/alerts")).json()
        assert [a["kind"] for a in alerts] == []


async def robot_held_still(server: RunningServer, name: str) -> bool:
    """The Task Manager gives the robot nothing while the alarm lasts."""
    tasks = server.app.state.task_manager
    robot = tasks.robots[name]
    return tasks.hold is not None and tasks.hold.holds(robot) and robot.current is None


async def test_declare_by_rest_checks_the_zone_and_survives_a_restart(tmp_path: Path) -> None:
    site = yaml.safe_load(DEMO_SITE.read_text(encoding="utf-8"))
    async with BuildingSimulator(load_building(site), time_scale=20, port_zero=True) as sim:
        for module in site["modules"]:
            module["port"] = sim.ports[module["id"]]
        (tmp_path / "site.yaml").write_text(yaml.safe_dump(site), encoding="utf-8")
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", site=tmp_path / "site.yaml"
        )
        async with running_server(settings) as server, serving(server) as http:
            bad = await http.post(
                "/api/emergency/declare", json={"zone": {"floors": ["F9"]}, "reason": "drill"}
            )
            assert bad.status_code == 422
            assert "unknown floor(s) F9 (the site's floors: F0, F1)" in bad.json()["detail"]
            both = await http.post(
                "/api/emergency/declare",
                json={"zone": {"floors": ["F0"], "areas": ["corridor"]}, "reason": "x"},
            )
            assert both.status_code == 422
            nothing = await http.post("/api/emergency/resume")
            assert nothing.status_code == 409 and "normal" in nothing.json()["detail"]
            declared = await http.post(
                "/api/emergency/declare", json={"zone": {"floors": ["F1"]}, "reason": "smoke on F1"}
            )
            assert declared.status_code == 200, declared.text
            assert declared.json()["declared_by"] == "admin"
            # outside the zone a door still opens (the ground floor carries on)
            emergency = server.app.state.emergency
            assert emergency.building_refusal("door_hall") is None
            assert "fire alarm" in (emergency.building_refusal("door_f1") or "")
            panel = await http.get("/api/emergency", headers={"Authorization": ""})
            assert panel.status_code == 401
        # A restart during the alarm keeps it (replayed from the event log).
        async with running_server(settings) as server, serving(server) as http:
            state = await _state(http)
            assert state["state"] == "alarm"
            assert state["zones"] == [{"floors": ["F1"]}] and state["reason"] == "smoke on F1"
            # ... and its staff alert, open again (the console's watcher starts after the
            # emergency service has published it).
            alerts = (await http.get("/api/alerts")).json()
            assert [a["message"] for a in alerts if a["kind"] == "fire_alarm"] == [
                "Fire alarm: floor F1 (declared by admin): robots go to their safe spots"
            ]
            resumed = await http.post("/api/emergency/resume")
            assert resumed.status_code == 200, resumed.text
            assert resumed.json()["state"] == "normal"


async def test_an_alarm_input_already_raised_at_start_is_declared(tmp_path: Path) -> None:
    """A module's first sample is no input change: the start reads the alarm inputs once."""
    site = yaml.safe_load(DEMO_SITE.read_text(encoding="utf-8"))
    async with BuildingSimulator(load_building(site), time_scale=20, port_zero=True) as sim:
        for module in site["modules"]:
            module["port"] = sim.ports[module["id"]]
        (tmp_path / "site.yaml").write_text(yaml.safe_dump(site), encoding="utf-8")
        sim.write(IORef(module="otb_ground", point="fire_alarm"), 1)
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", site=tmp_path / "site.yaml"
        )
        async with running_server(settings) as server, serving(server) as http:
            recorder = Recorder(server.app.state.hub.endpoint("test"), "emergency_changed")
            await wait_until(lambda: server.app.state.emergency.state == "alarm")
            assert (await _state(http))["declared_by"] == "input:fire_main"
            sim.write(IORef(module="otb_ground", point="fire_alarm"), 0)
            await recorder.wait("emergency_changed", state="input_clear")
            assert (await http.post("/api/emergency/resume")).status_code == 200


async def test_a_robot_connecting_or_restarting_during_the_alarm_hears_of_it(
    tmp_path: Path,
) -> None:
    """The broadcast went out before these processes were there: each is told on its first
    state, and a restarted agent (new boot id) is ordered to safety again."""
    async with alarm_rig(tmp_path) as (_sim, server, _control, http):
        hub = server.app.state.hub
        declared = await http.post(
            "/api/emergency/declare", json={"zone": {"floors": ["F1"]}, "reason": "smoke on F1"}
        )
        assert declared.status_code == 200, declared.text
        # Outside the zone: no order, but the screen must know new requests are refused.
        below = RobotStub(hub, "R1", "hall")
        below.state(boot_id="r1-first")
        told = await below.wait_for("emergency_changed")
        assert told.payload["state"] == "alarm" and told.payload["zones"] == [{"floors": ["F1"]}]
        assert below.of_type("evacuate") == []
        # Inside the zone: told and ordered; safe at its spot.
        above = RobotStub(hub, "R2", "gc1")
        above.state(boot_id="r2-first")
        await above.wait_for("emergency_changed")
        first = await above.wait_for("evacuate")
        above.endpoint.publish(
            "evacuation_state", {"state": "safe", "node": first.payload["safe_spot"]}
        )
        emergency = server.app.state.emergency
        await wait_until(lambda: emergency.evacuation["R2"]["state"] == "safe")
        # The same process reporting again is not told twice.
        above.state(boot_id="r2-first")
        below.state(boot_id="r1-first")
        # Its agent restarts (same name, new process): it forgot its order and the alarm.
        above.node = first.payload["safe_spot"]
        above.state(boot_id="r2-second")
        again = await above.wait_for("evacuate", count=2)
        assert again.payload["safe_spot"] == first.payload["safe_spot"]
        await above.wait_for("emergency_changed", count=2)
        assert len(below.of_type("emergency_changed")) == 1


@pytest.mark.parametrize("active_when", [1, 0], ids=["normally-open", "normally-closed"])
async def test_the_alarm_input_is_read_on_its_own_poll(tmp_path: Path, active_when: int) -> None:
    """The fire alarm does not wait for its module's whole poll: its input is also read on its
    own, every ALARM_POLL_MS (docs/emergency.md, "Measured"). Here the module's own poll
    comes once a minute (its first a minute after start): the alarm is declared before it,
    from either contact of the panel's relay."""
    site = yaml.safe_load(DEMO_SITE.read_text(encoding="utf-8"))
    ground = next(m for m in site["modules"] if m["id"] == "otb_ground")
    ground["sampling_period_ms"] = 60_000
    site["emergency"]["alarms"][0]["active_when"] = active_when
    alarm = IORef(module="otb_ground", point="fire_alarm")
    async with BuildingSimulator(load_building(site), time_scale=20, port_zero=True) as sim:
        sim.write(alarm, 1 - active_when)  # all is well
        for module in site["modules"]:
            module["port"] = sim.ports[module["id"]]
        (tmp_path / "site.yaml").write_text(yaml.safe_dump(site), encoding="utf-8")
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", site=tmp_path / "site.yaml"
        )
        async with running_server(settings) as server:
            building = server.app.state.building
            assert set(building.alarm_pollers) == {"otb_ground"}
            own = building.alarm_pollers["otb_ground"]
            await wait_until(lambda: own.health.polls > 0)
            polls = building.pollers["otb_ground"].health.polls
            await wait_until(lambda: building.values.get(("otb_ground", "fire_alarm")) is not None)
            assert server.app.state.emergency.state == "normal"
            sim.write(alarm, active_when)
            await wait_until(lambda: server.app.state.emergency.state == "alarm")
            assert building.pollers["otb_ground"].health.polls == polls
            # That poll reads the alarm input alone (the module's poll reads every point).
            assert own.module.points == [
                p for p in building.config.module("otb_ground").points if p.name == "fire_alarm"
            ]
