"""Known gaps closed: offline lock holders, requeue after a robot loss, staff alerts."""

from __future__ import annotations

import asyncio
import logging
import time
from pathlib import Path

import pytest

from backend.tasks import TaskManager, TaskState
from backend.testing import running_server
from backend.traffic import LockState, TrafficManager
from guidebot.bus import Bus
from guidebot.client import HubClient
from guidebot.messages import Message

from .conftest import GUI_TOKEN, Clock, server_settings
from .helpers import RobotStub, demo_site
from .test_tasks import fleet

GRACE = 30.0


async def start_traffic(bus: Bus) -> tuple[TrafficManager, list[Message]]:
    traffic = TrafficManager(bus.endpoint("traffic_manager"), demo_site())
    await traffic.start()
    alerts: list[Message] = []
    bus.endpoint("console").subscribe("alert_*", alerts.append)
    return traffic, alerts


async def test_lock_of_a_robot_that_went_offline_before_entering_is_released(
    caplog: pytest.LogCaptureFixture,
) -> None:
    bus = Bus()
    traffic, alerts = await start_traffic(bus)
    r1, r2 = RobotStub(bus, "R1", "ga2"), RobotStub(bus, "R2", "gb1")
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "corridor"})
    r1.state("busy")  # granted, still outside at ga2, two steps from the corridor
    bus.endpoint("link_watcher").publish("robot_disconnected", {"robot": "R1"})
    caplog.set_level(logging.INFO)
    r2.endpoint.publish("request_area", {"robot": "R2", "area": "corridor"})
    waited = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert any("R2 waits for corridor (held by R1)" in m and "offline" in m for m in waited)
    traffic.check_offline_locks(GRACE, now=time.monotonic() + GRACE / 2)
    assert traffic.locks.holder("corridor") == "R1" and not alerts  # grace not over
    traffic.check_offline_locks(GRACE, now=time.monotonic() + GRACE + 1)
    await r2.wait_for("area_granted")
    assert traffic.locks.holder("corridor") == "R2"
    [alert] = alerts
    assert alert.type == "alert_raised" and alert.payload["kind"] == "lock_released_offline"
    assert alert.payload["subject"] == "corridor" and "R1 went offline" in alert.payload["message"]
    assert "never seen inside" in alert.payload["message"]
    assert alert.payload["lasting"] is False  # a notice: acknowledging it resolves it
    assert any(
        r.levelno == logging.WARNING and "lock_released_offline" in r.getMessage()
        for r in caplog.records
    )


async def test_offline_holder_last_seen_at_the_areas_edge_keeps_the_lock() -> None:
    """At ga1, one step from the corridor, R1 may have driven in after its link dropped
    (found by the 30-minute soak: two robots in one corridor after a link cut)."""
    bus = Bus()
    traffic, alerts = await start_traffic(bus)
    r1, r2 = RobotStub(bus, "R1", "ga1"), RobotStub(bus, "R2", "gb1")
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "corridor"})
    r1.state("busy")
    bus.endpoint("link_watcher").publish("robot_disconnected", {"robot": "R1"})
    r2.endpoint.publish("request_area", {"robot": "R2", "area": "corridor"})
    traffic.check_offline_locks(GRACE, now=time.monotonic() + GRACE + 1)
    assert traffic.locks.holder("corridor") == "R1" and not r2.of_type("area_granted")
    [alert] = alerts
    assert alert.payload["kind"] == "lock_holder_offline"


async def test_offline_holder_that_may_be_inside_keeps_the_lock_and_staff_are_alerted() -> None:
    bus = Bus()
    traffic, alerts = await start_traffic(bus)
    r1, r2 = RobotStub(bus, "R1", "ga1"), RobotStub(bus, "R2", "gb1")
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "corridor"})
    r1.node = "corridor_w"
    r1.state("busy")  # inside
    r1.state("offline")
    r2.endpoint.publish("request_area", {"robot": "R2", "area": "corridor"})
    later = time.monotonic() + GRACE + 1
    traffic.check_offline_locks(GRACE, now=later)
    traffic.check_offline_locks(GRACE, now=later + 5)  # checked again: one alert, not two
    view = next(v for v in traffic.lock_views() if v.area == "corridor")
    assert view.state is LockState.HOLDER_OFFLINE and view.holder == "R1"
    assert not r2.of_type("area_granted")
    [alert] = alerts
    assert alert.type == "alert_raised" and alert.payload["kind"] == "lock_holder_offline"
    assert alert.payload["severity"] == "error" and alert.payload["subject"] == "corridor"
    assert [a.kind for a in traffic.alerts.active()] == ["lock_holder_offline"]
    r1.state("busy")  # back online: the alert resolves itself, under the same id
    assert alerts[-1].type == "alert_resolved" and alerts[-1].payload["id"] == alert.payload["id"]
    assert "R1 is back online" in alerts[-1].payload["resolution"]
    assert not traffic.alerts.active()


async def test_robot_inside_an_area_another_holds_raises_a_conflict_alert() -> None:
    bus = Bus()
    traffic, alerts = await start_traffic(bus)
    r1, r2 = RobotStub(bus, "R1", "ga1"), RobotStub(bus, "R2", "gb1")
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "corridor"})
    r2.node = "corridor_e"
    r2.state("busy")
    r2.state("busy")
    [alert] = alerts
    assert alert.payload["kind"] == "area_conflict" and alert.payload["subject"] == "R2"
    r2.node = "gb1"
    r2.state("busy")
    assert alerts[-1].type == "alert_resolved" and not traffic.alerts.active()


def lost_robot_scene(bus: Bus, manager: TaskManager, clock: Clock) -> tuple[str, RobotStub]:
    """R3 runs a tour, falls silent past the grace period: the tour is requeued."""
    r1, r2, r3 = fleet(bus)
    busy_1 = manager.request("go_to", {"node": "gc3"}, robot="R1")  # upstairs, far away
    busy_2 = manager.request("go_to", {"node": "gb1"}, robot="R2")
    r1.start(busy_1.id)
    r2.start(busy_2.id)
    task = manager.request("tour", {"tour": "ground"})
    assert task.robot == "R3"
    r3.start(task.id)
    clock.now += 6
    r1.state("busy")
    r2.state("busy")
    manager.check_timeouts()
    clock.now += 21
    r1.state("busy")
    r2.state("busy")
    manager.check_timeouts()
    assert task.state is TaskState.QUEUED
    return task.id, r3


async def test_requeued_task_goes_to_the_returning_robot_when_no_other_is_free(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    task_id, r3 = lost_robot_scene(bus, manager, clock)
    r3.task_id = None
    r3.state()  # back, idle and healthy; R1 and R2 are busy
    assert manager.get(task_id).robot == "R3"  # the visitor does not wait for R1 or R2


async def test_requeued_task_prefers_another_robot_when_one_is_free(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    task_id, _r3 = lost_robot_scene(bus, manager, clock)
    back = manager.robots["R3"]  # back without a dispatch yet, nearer the tour than R1
    back.online, back.mode, back.last_seen, back.node = True, "idle", clock.now, "hall"
    r1 = manager.robots["R1"]
    busy = manager.get(r1.current or "")
    bus.get_endpoint("R1").publish(  # type: ignore[union-attr]
        "task_ended", {"task_id": busy.id, "robot": "R1", "outcome": "done"}
    )
    assert manager.get(task_id).robot == "R1"


async def test_a_task_whose_robot_left_before_acknowledging_is_sent_again_on_its_return(
    bus: Bus, manager: TaskManager
) -> None:
    r1, _r2, _r3 = fleet(bus)
    manager.set_out_of_service("R2", True)
    manager.set_out_of_service("R3", True)
    task = manager.request("go_to_poi", {"poi": "loom"}, requester="panel-1")
    first = await r1.wait_for("task_assigned")
    bus.endpoint("link_watcher").publish("robot_disconnected", {"robot": "R1"})
    r1.state()  # back, and it does not run the task: its copy went with the link
    again = await r1.wait_for("task_assigned", count=2)
    assert again.payload == first.payload and manager.get(task.id).state is TaskState.ASSIGNED
    r1.task_id = task.id
    r1.state()  # running it now: nothing more is sent
    assert len(r1.of_type("task_assigned")) == 2


async def test_robots_joining_and_leaving_are_announced_by_a_hub_event(tmp_path: Path) -> None:
    async with running_server(server_settings(tmp_path)) as srv:
        async with HubClient(srv.ws_url, GUI_TOKEN) as gui:
            seen: asyncio.Queue[Message] = asyncio.Queue()
            gui.subscribe("robot_*connected", seen.put_nowait)
            await gui.sync()
            r1 = HubClient(srv.ws_url, "robot-R1-demo-token")
            await r1.start()
            joined = await asyncio.wait_for(seen.get(), 10)
            assert (joined.type, joined.payload, joined.source) == (
                "robot_connected",
                {"robot": "R1"},
                "link_watcher",
            )
            await r1.close()
            left = await asyncio.wait_for(seen.get(), 10)
            assert (left.type, left.payload) == ("robot_disconnected", {"robot": "R1"})
            await gui.sync()
            assert seen.empty()  # the GUI's own connection is not a robot's
