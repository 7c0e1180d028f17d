"""What raises and resolves each alert (backend/console/alerts.py), message by message: every
alert resolves itself when a message says its cause is gone."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from backend.alerts import AlertStore
from backend.console.alerts import AlertWatcher
from guidebot.bus import Bus


@pytest.fixture
async def rig() -> AsyncIterator[tuple[Bus, AlertStore]]:
    bus = Bus()
    alerts = AlertStore(bus.endpoint("alerts").publish)
    async with AlertWatcher(bus.endpoint("alert_watcher"), alerts):
        yield bus, alerts


def active(alerts: AlertStore) -> set[tuple[str, str]]:
    return {(a.kind, a.subject) for a in alerts.active()}


def state(robot: str, **extra: object) -> dict[str, object]:
    return {"robot": robot, "mode": "busy", "navigation": "moving", "battery": 0.8, **extra}


async def test_robot_alerts_resolve_when_the_robot_says_so(rig: tuple[Bus, AlertStore]) -> None:
    bus, alerts = rig
    link, r1 = bus.endpoint("link_watcher"), bus.endpoint("R1")
    link.publish("robot_disconnected", {"robot": "R1"})
    r1.publish("battery_panic", {"robot": "R1", "level": 0.08})
    r1.publish("robot_fault", {"robot": "R1", "kind": "door_blocked", "detail": "door d1"})
    r1.publish("robot_fault", {"robot": "R1", "kind": "motor_lost", "detail": "left wheel"})
    still = {"mode": "fault", "navigation": "door_blocked", "battery": 0.1}
    r1.publish("robot_state", state("R1", modules={"head": "lost"}, **still))
    assert active(alerts) == {  # robot_lost resolved: a state from it says it is back
        ("battery_panic", "R1"),
        ("robot_fault", "R1/door_blocked"),
        ("robot_fault", "R1/motor_lost"),
        ("can_module_lost", "R1/head"),
    }
    r1.publish("robot_state", state("R1", mode="fault", modules={"head": "ok"}, battery=0.1))
    assert active(alerts) == {("battery_panic", "R1"), ("robot_fault", "R1/motor_lost")}
    r1.publish("robot_state", state("R1", battery=0.12))  # out of fault, not yet charged
    assert active(alerts) == {("battery_panic", "R1")}
    r1.publish("robot_state", state("R1", battery=0.2))  # charged past the panic level
    assert not active(alerts)
    # A robot that says it is leaving, then goes: no alert; one that just drops: lost.
    r1.publish("robot_state", state("R1", mode="offline"))
    link.publish("robot_disconnected", {"robot": "R1"})
    assert not active(alerts)
    link.publish("robot_connected", {"robot": "R1"})
    link.publish("robot_disconnected", {"robot": "R1"})
    assert active(alerts) == {("robot_lost", "R1")}
    link.publish("robot_connected", {"robot": "R1"})
    assert not active(alerts)


async def test_building_alerts_resolve_when_the_device_does_it(
    rig: tuple[Bus, AlertStore],
) -> None:
    bus, alerts = rig
    building = bus.endpoint("building")
    for command, target in (
        ("open_door", "d1"),
        ("close_door", "d1"),
        ("call_elevator", "lift"),
        ("set_output", "M1/lamp"),
    ):
        building.publish("command_failed", {"command": command, "reason": "x", "target": target})
    building.publish(
        "building_module_health", {"module": "M1", "online": False, "last_error": "timeout"}
    )
    building.publish("building_module_health", {"module": "M1", "online": False})
    assert alerts.get("module_offline", "M1").count == 1  # reported again: not counted
    assert len(active(alerts)) == 5
    building.publish("door_opened", {"door": "d1"})
    building.publish("door_closed", {"door": "d1", "sensed": False})  # not known closed
    building.publish("elevator_in_position", {"elevator": "lift", "floor": "F0", "door_open": 0})
    assert ("building_command_failed", "open_door:d1") not in active(alerts)
    assert ("building_command_failed", "close_door:d1") in active(alerts)
    assert ("building_command_failed", "call_elevator:lift") in active(alerts)
    building.publish("door_closed", {"door": "d1", "sensed": True})
    building.publish("elevator_in_position", {"elevator": "lift", "floor": "F1", "door_open": 1})
    building.publish("building_input_changed", {"module": "M1", "point": "lamp", "value": True})
    building.publish("building_module_health", {"module": "M1", "online": True})
    assert not active(alerts)


async def test_lock_and_task_alerts(rig: tuple[Bus, AlertStore]) -> None:
    bus, alerts = rig
    console = bus.endpoint("console")
    console.publish("lock_changed", {"area": "corridor", "state": "holder_offline", "holder": "R1"})
    console.publish("lock_changed", {"area": "corridor", "state": "holder_offline", "holder": "R1"})
    lock = alerts.get("lock_holder_offline", "corridor")
    assert lock is not None and lock.count == 1 and lock.open
    console.publish("lock_changed", {"area": "corridor", "state": "held", "holder": "R1"})
    assert not lock.active and lock.resolution == "area corridor is held (R1)"
    bus.endpoint("task_manager").publish("task_event", {"task_id": "t1", "state": "failed"})
    failed = alerts.get("task_failed", "t1")
    assert failed is not None and failed.severity == "warning" and not failed.lasting
    alerts.acknowledge(failed.id, "desk")
    assert not active(alerts)


async def test_the_fire_alarm_and_a_stuck_evacuation_are_alerts_until_resumed(
    rig: tuple[Bus, AlertStore],
) -> None:
    bus, alerts = rig
    emergency, r1 = bus.endpoint("emergency"), bus.endpoint("R1")
    alarm = {"state": "alarm", "zones": [{}], "declared_by": "input:fire_main", "since": 1.0}
    emergency.publish("emergency_changed", alarm)
    (alert,) = alerts.active()
    assert (alert.kind, alert.subject) == ("fire_alarm", "site")
    assert alert.message.startswith(
        "Fire alarm: the whole site (declared by alarm input fire_main)"
    )
    emergency.publish("emergency_changed", alarm)  # said again (a client connects): no count
    assert alerts.get("fire_alarm", "site").count == 1  # type: ignore[union-attr]
    emergency.publish("emergency_changed", {**alarm, "zones": [{}, {"floors": ["F1"]}]})
    assert "the whole site; floor F1" in alert.message and alert.count == 2
    r1.publish("evacuation_state", {"state": "stuck", "node": "gc2", "why": "bumper"})
    assert active(alerts) == {("fire_alarm", "site"), ("evacuation_stuck", "R1")}
    assert alerts.get("evacuation_stuck", "R1").message == (  # type: ignore[union-attr]
        "R1 is stuck on its way to safety at gc2: bumper"
    )
    r1.publish("evacuation_state", {"state": "moving", "node": "gc2"})
    assert active(alerts) == {("fire_alarm", "site")}
    r1.publish("evacuation_state", {"state": "stuck", "node": "gc2", "why": "bumper"})
    emergency.publish("emergency_changed", {**alarm, "state": "input_clear"})
    assert active(alerts) == {("fire_alarm", "site"), ("evacuation_stuck", "R1")}
    emergency.publish("emergency_changed", {"state": "normal"})
    assert not active(alerts)
    assert alert.resolution == "service resumed after the fire alarm"
