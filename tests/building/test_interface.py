"""BuildingInterface against building_sim over real Modbus/TCP on loopback."""

from __future__ import annotations

import asyncio
import time

from backend.building.interface import BuildingInterface
from building_sim.simulator import BuildingSimulator
from guidebot.bus import Bus
from guidebot.site.building_config import BuildingConfig, load_building
from guidebot.testing import Recorder, wait_until

from .conftest import TIME_SCALE, site_dict


async def test_300ms_press_gives_one_event(
    sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    sim.press("B1", ms=300)
    pressed = await recorder.wait("building_input_changed", point="b1", value=True)
    assert pressed.payload["module"] == "M1"
    assert pressed.payload["node"] == "hall"
    await recorder.wait("building_input_changed", point="b1", value=False)
    assert len(recorder.of("building_input_changed", point="b1", value=True)) == 1


async def test_100ms_pulse_is_filtered_out(
    sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    poller = interface.pollers["M1"]
    sim.press("B1", ms=100)
    await wait_until(lambda: not sim.state()["buttons"]["B1"])
    polls = poller.health.polls
    # Several more samples after the release: the filter has had every chance to fire.
    await wait_until(lambda: poller.health.polls >= polls + 6)
    assert recorder.of("building_input_changed", point="b1") == []


def stall_the_process(seconds: float) -> None:
    """Block the event loop as a loaded machine's scheduler does: nothing in the process runs."""
    time.sleep(seconds)


async def test_a_press_during_a_stall_of_the_process_is_still_seen(
    sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    """The test fleets run the simulator and the server's poller in one process: a stall froze
    the poller but not the press, whose release came first after it (a console press lost, CI).
    The simulated hand freezes too, as the simulated base does."""
    poller = interface.pollers["M1"]
    sim.press("B1", ms=400)
    polls = poller.health.polls
    # Two polls done: the second was sent after the press (the first may have been under way
    # before it), so the filter is timing the press.
    await wait_until(lambda: poller.health.polls >= polls + 2)
    stall_the_process(1.0)
    await recorder.wait("building_input_changed", point="b1", value=True)
    await recorder.wait("building_input_changed", point="b1", value=False)


async def test_open_door_is_confirmed_to_the_requester_and_broadcast(
    hub: Bus, sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    robot = hub.endpoint("R1")
    reply = await robot.request("open_door", {"door": "D1"}, timeout=10)
    assert reply.type == "door_opened"
    assert reply.payload == {"door": "D1"}
    assert sim.doors["D1"].state == "open"
    await recorder.wait("door_opened", door="D1")
    # This simulator's door closes by itself after its hold time: the fleet is told.
    await recorder.wait("building_input_changed", point="d1_open", value=False)
    await recorder.wait("door_closed", door="D1")


async def test_a_door_stays_open_until_its_last_holder_releases_it(
    hub: Bus, building: BuildingConfig, recorder: Recorder
) -> None:
    async with (
        BuildingSimulator(building, time_scale=TIME_SCALE, port_zero=True) as sim,
        BuildingInterface(hub.endpoint("building"), sim.bound_config()) as bi,
    ):
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        r1, r2 = hub.endpoint("R1"), hub.endpoint("R2")
        assert (await r1.request("open_door", {"door": "D1"}, timeout=10)).type == "door_opened"
        assert (await r2.request("open_door", {"door": "D1"}, timeout=10)).type == "door_opened"
        assert sorted(bi.doors["D1"].holders) == ["R1", "R2"]
        r1.publish("release_door", {"door": "D1"})
        polls = bi.pollers["M1"].health.polls
        await wait_until(lambda: bi.pollers["M1"].health.polls >= polls + 4)
        assert sim.doors["D1"].state == "open" and bi.doors["D1"].is_open
        r2.publish("release_door", {"door": "D1"})
        await recorder.wait("door_closed", door="D1")
        await wait_until(lambda: sim.doors["D1"].state == "closed")
        # Closed means closed at once: no stale "open" sample brings it back.
        await wait_until(lambda: bi.pollers["M1"].health.polls >= polls + 8)
        assert bi.doors["D1"].is_open is False
        assert [m.type for m in recorder.messages if m.type.startswith("door_")][-1] == (
            "door_closed"
        )


async def test_a_door_without_sensor_counts_open_after_its_open_time(
    hub: Bus, recorder: Recorder
) -> None:
    data = site_dict()
    del data["building"]["doors"][0]["is_open"]
    data["building"]["doors"][0]["open_time_s"] = 0.3
    building = load_building(data)
    async with (
        BuildingSimulator(building, time_scale=TIME_SCALE, port_zero=True) as sim,
        BuildingInterface(hub.endpoint("building"), sim.bound_config()) as bi,
    ):
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        robot = hub.endpoint("R1")
        loop = asyncio.get_running_loop()
        asked = loop.time()
        assert (await robot.request("open_door", {"door": "D1"}, timeout=10)).type == "door_opened"
        assert loop.time() - asked >= 0.3
        assert bi.doors["D1"].is_open
        robot.publish("release_door", {"door": "D1"})
        await recorder.wait("door_closed", door="D1")
        await wait_until(lambda: sim.read_point("M1", "d1_cmd") == 0)


async def test_a_jammed_door_fails_with_a_reason_and_is_not_left_energised(
    hub: Bus, building: BuildingConfig, recorder: Recorder
) -> None:
    async with (
        BuildingSimulator(building, time_scale=TIME_SCALE, port_zero=True) as sim,
        BuildingInterface(hub.endpoint("building"), sim.bound_config(), command_margin_s=0.5) as bi,
    ):
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        sim.jam_door("D1")
        reply = await hub.endpoint("R1").request("open_door", {"door": "D1"}, timeout=15)
        assert reply.type == "command_failed"
        assert reply.payload["command"] == "open_door"
        assert "door D1 not open within" in reply.payload["reason"]
        assert bi.doors["D1"].holders == {}
        await wait_until(lambda: sim.read_point("M1", "d1_cmd") == 0)


async def test_a_door_let_go_before_it_opened_is_not_a_door_that_failed(
    hub: Bus, building: BuildingConfig, recorder: Recorder
) -> None:
    """The virtual plan day (demo museum, 300 visitors, 2 robots) saw door_gallery "not open
    within 7 s" at 5.6 h: a robot asked it open, its charge was pre-empted by a tour the next
    moment and it let the door go; the open_door kept waiting, and its time-out was published as
    a door failure (a trouble closure, an alert, the robot's next task failed on it). The
    request is withdrawn when its holder lets go: no command_failed, nothing left waiting."""
    async with (
        BuildingSimulator(building, time_scale=TIME_SCALE, port_zero=True) as sim,
        BuildingInterface(hub.endpoint("building"), sim.bound_config(), command_margin_s=0.5) as bi,
    ):
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        sim.jam_door("D1")  # it cannot open before it is let go, however slow the machine
        robot = hub.endpoint("R1")
        answers = Recorder(robot, "command_failed", "door_opened")
        robot.publish("open_door", {"door": "D1"})
        await wait_until(lambda: sim.read_point("M1", "d1_cmd") == 1)
        robot.publish("release_door", {"door": "D1"})
        await wait_until(lambda: not bi._commands)  # the open_door's handler is done
        assert answers.messages == [] and recorder.of("command_failed") == []
        assert bi.doors["D1"].holders == {}
        await wait_until(lambda: sim.read_point("M1", "d1_cmd") == 0)
        # The door works: the robot's next open_door is answered as ever.
        sim.jam_door("D1", False)
        reply = await robot.request("open_door", {"door": "D1"}, timeout=10)
        assert reply.type == "door_opened"


async def test_the_fire_alarm_dropping_a_door_withdraws_the_open_doors_waiting_for_it(
    hub: Bus, building: BuildingConfig, recorder: Recorder
) -> None:
    """The fire alarm lets go of the zone's doors (``drop_door_holders``); the open_door
    requests still waiting for one kept waiting, and their time-out was published as a door
    failure (a trouble closure and an alert mid-evacuation, for a door nobody wanted any more).
    Those of the robots it evacuates (R1) are withdrawn, as when their robot lets go: no
    command_failed, nothing left waiting. A robot outside its zone (R2) still wants the door:
    it is refused at once with the alarm's reason, not left waiting unanswered."""
    async with (
        BuildingSimulator(building, time_scale=TIME_SCALE, port_zero=True) as sim,
        BuildingInterface(hub.endpoint("building"), sim.bound_config(), command_margin_s=0.5) as bi,
    ):
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        sim.jam_door("D1")  # it cannot open before the alarm, however slow the machine
        robots = [hub.endpoint(name) for name in ("R1", "R2")]
        answers = [Recorder(robot, "command_failed", "door_opened") for robot in robots]
        for robot in robots:
            robot.publish("open_door", {"door": "D1"})
        await wait_until(lambda: set(bi.doors["D1"].holders) == {"R1", "R2"})
        await wait_until(lambda: sim.read_point("M1", "d1_cmd") == 1)
        assert bi.drop_door_holders({"d1"}, evacuating={"R1"}) == ["D1"]
        await wait_until(lambda: not bi._commands)  # both open_doors and the close are done
        assert answers[0].messages == []
        [refused] = answers[1].messages
        assert refused.type == "command_failed" and refused.payload["target"] == "D1"
        assert refused.payload["reason"].startswith("fire alarm"), refused.payload
        assert bi.doors["D1"].holders == {}
        assert sim.read_point("M1", "d1_cmd") == 0


async def test_a_door_released_while_its_module_is_offline_is_closed_once_it_is_back(
    hub: Bus, building: BuildingConfig, recorder: Recorder
) -> None:
    """The coil could not be cleared at the release: when the module answers again it is,
    else the building would keep the door open for ever (found by the soak). Meanwhile the
    door may stand open, but it is not announced open: the interface is about to close it, and
    a robot told "open" would drive into a closing door (the soak saw it)."""
    async with (
        BuildingSimulator(building, time_scale=TIME_SCALE, port_zero=True) as sim,
        BuildingInterface(hub.endpoint("building"), sim.bound_config()) as bi,
    ):
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        robot = hub.endpoint("R1")
        opened = await robot.request("open_door", {"door": "D1"}, timeout=10)
        assert opened.type == "door_opened"
        await sim.set_fault("M1", "offline")
        await wait_until(lambda: not bi.pollers["M1"].health.online, timeout=20)
        reply = await robot.request("release_door", {"door": "D1"}, timeout=10)
        assert reply.type == "command_failed" and "M1 is offline" in reply.payload["reason"]
        assert sim.read_point("M1", "d1_cmd") == 1  # still set: nobody could reach the module
        released = len(recorder.messages)
        await sim.set_fault("M1", "none")
        await wait_until(lambda: sim.read_point("M1", "d1_cmd") == 0, timeout=30)
        await wait_until(lambda: sim.doors["D1"].state in ("closing", "closed"))
        await wait_until(lambda: bi.pollers["M1"].health.online)
        assert not [m for m in recorder.messages[released:] if m.type == "door_opened"]
        assert bi.doors["D1"].is_open is False
        # And the door is the fleet's again: a new open_door opens it.
        assert (await robot.request("open_door", {"door": "D1"}, timeout=10)).type == "door_opened"


async def test_an_open_door_whose_module_goes_offline_is_closed_but_not_sensed(
    hub: Bus, building: BuildingConfig, recorder: Recorder
) -> None:
    """Unknown is closed for the robots, but the fleet is told it was not sensed: the door
    may still stand open (nobody can clear its coil), so no one may call it a closed door."""
    async with (
        BuildingSimulator(building, time_scale=TIME_SCALE, port_zero=True) as sim,
        BuildingInterface(hub.endpoint("building"), sim.bound_config()) as bi,
    ):
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        robot = hub.endpoint("R1")
        assert (await robot.request("open_door", {"door": "D1"}, timeout=10)).type == "door_opened"
        recorder.messages.clear()
        await sim.set_fault("M1", "offline")
        closed = await recorder.wait("door_closed", door="D1")
        assert closed.payload["sensed"] is False
        assert sim.doors["D1"].state == "open"  # physically still open
        await sim.set_fault("M1", "none")
        await recorder.wait("door_opened", door="D1")  # sensed again, and still held
        recorder.messages.clear()
        assert (await robot.request("close_door", {"door": "D1"}, timeout=10)).type == "door_closed"
        await recorder.wait("door_closed", door="D1", sensed=True)  # the broadcast: sensed


async def test_close_door_is_confirmed(
    hub: Bus, sim: BuildingSimulator, interface: BuildingInterface
) -> None:
    robot = hub.endpoint("R1")
    assert (await robot.request("open_door", {"door": "D1"}, timeout=10)).type == "door_opened"
    reply = await robot.request("close_door", {"door": "D1"}, timeout=10)
    assert reply.type == "door_closed"
    assert sim.doors["D1"].state in ("closing", "closed")


async def test_elevator_call_is_confirmed_at_the_right_floor(
    hub: Bus, sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    robot = hub.endpoint("R1")
    reply = await robot.request("call_elevator", {"elevator": "E1", "floor": "2"}, timeout=15)
    assert reply.type == "elevator_in_position"
    assert reply.payload == {"elevator": "E1", "floor": "2", "door_open": True}
    assert sim.elevators["E1"].floor == "2"
    assert sim.elevators["E1"].state == "door_open"
    changed = recorder.of("building_input_changed", point="e1_at_2", value=True)
    assert changed[0].payload["floor"] == "2"
    # The floor register followed the cabin (index of the stop).
    await recorder.wait("building_input_changed", point="E1_floor", value=2)


async def test_unknown_door_and_floor_fail_with_a_reason(
    hub: Bus, interface: BuildingInterface
) -> None:
    robot = hub.endpoint("R1")
    reply = await robot.request("open_door", {"door": "NOPE"}, timeout=5)
    assert reply.type == "command_failed"
    assert reply.payload["command"] == "open_door"
    assert "unknown door 'NOPE'" in reply.payload["reason"]
    reply = await robot.request("call_elevator", {"elevator": "E1", "floor": "9"}, timeout=5)
    assert reply.type == "command_failed"
    assert "no floor '9'" in reply.payload["reason"]
    reply = await robot.request("open_door", {"gate": "D1"}, timeout=5)
    assert reply.type == "command_failed"
    assert reply.payload["reason"].startswith("bad payload")


async def test_set_output_writes_a_coil_and_refuses_an_input(
    hub: Bus, sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    operator = hub.endpoint("admin")
    operator.publish("set_output", {"module": "M2", "point": "lamp", "value": True})
    await recorder.wait("building_input_changed", module="M2", point="lamp", value=True)
    assert sim.state()["modules"]["M2"]["points"]["lamp"] == 1
    reply = await operator.request("set_output", {"module": "M2", "point": "b2", "value": 1})
    assert reply.type == "command_failed"
    assert "read-only" in reply.payload["reason"]


async def test_offline_module_is_reported_and_recovers_by_itself(
    hub: Bus, sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    await recorder.wait("building_module_health", module="M2", online=True)
    await sim.set_fault("M2", "offline")
    down = await recorder.wait("building_module_health", module="M2", online=False)
    assert down.payload["errors"] >= 1
    assert down.payload["last_error"]
    # A command to an offline module fails at once with the reason.
    reply = await hub.endpoint("admin").request(
        "set_output", {"module": "M2", "point": "lamp", "value": 1}
    )
    assert reply.type == "command_failed"
    assert "offline" in reply.payload["reason"]
    # The other module keeps working meanwhile.
    sim.press("B1", ms=400)
    await recorder.wait("building_input_changed", point="b1", value=True)
    recorder.messages.clear()
    await sim.set_fault("M2", "none")
    up = await recorder.wait("building_module_health", module="M2", online=True)
    assert up.payload["rtt_ms"] is not None
    sim.press("B2", ms=400)
    await recorder.wait("building_input_changed", point="b2", value=True)


async def test_exception_answer_is_reported_and_others_keep_polling(
    sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    await sim.set_fault("M2", "exception", code=4)
    faulty = await recorder.wait("building_module_health", module="M2", online=False)
    assert "Modbus exception 4 (device failure)" in faulty.payload["last_error"]
    m1 = interface.pollers["M1"].health
    polls = m1.polls
    await wait_until(lambda: m1.polls >= polls + 5)
    sim.press("B1", ms=400)
    await recorder.wait("building_input_changed", point="b1", value=True)
    # M2 is still polled (its error count grows), and recovers when the fault clears.
    m2 = interface.pollers["M2"].health
    errors = m2.errors
    await wait_until(lambda: m2.errors > errors)
    await sim.set_fault("M2", "none")
    await recorder.wait("building_module_health", module="M2", online=True)


async def test_slow_module_does_not_delay_the_others(
    sim: BuildingSimulator, interface: BuildingInterface, recorder: Recorder
) -> None:
    await sim.set_fault("M2", "slow", delay_ms=150)
    m1, m2 = interface.pollers["M1"], interface.pollers["M2"]
    await wait_until(lambda: (m2.health.rtt_ms or 0) >= 150)
    start = len(m1.jitter_s)
    await wait_until(lambda: len(m1.jitter_s) >= start + 10)
    # M1 kept polling on its own while each of M2's polls (two tables, 150 ms each) overran.
    assert m1.health.rtt_ms is not None and m2.health.rtt_ms is not None
    assert m1.health.rtt_ms < m2.health.rtt_ms
    assert m2.health.overruns > 0


async def test_an_elevator_call_waits_for_a_busy_cabin_and_fails_only_when_it_is_stuck(
    hub: Bus,
) -> None:
    """A cabin holding its door open at another floor, then travelling, takes longer than
    travel_time_s plus the margin (the demo's rides of ~20 s failed at 17 s, a false alarm):
    the call waits while the cabin makes progress; a stuck cabin still fails."""
    site = site_dict()
    site["building"]["elevators"][0]["travel_time_s"] = 2.0  # 1 s a floor
    config = load_building(site)
    async with (
        BuildingSimulator(config, port_zero=True, elevator_hold_s=1.5) as sim,
        BuildingInterface(
            hub.endpoint("building"),
            sim.bound_config(),
            filter_ms=200,
            health_interval_s=1.0,
            command_margin_s=1.0,  # no progress for 3 s: the call fails
        ) as bi,
    ):
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        robot = hub.endpoint("R1")
        up = await robot.request("call_elevator", {"elevator": "E1", "floor": "2"}, timeout=15)
        assert up.type == "elevator_in_position"
        # Door open at floor 2 for 1.5 s, then 2 s down: ~4 s, more than 2 + 1 s.
        down = await robot.request("call_elevator", {"elevator": "E1", "floor": "0"}, timeout=15)
        assert down.type == "elevator_in_position", down.payload
        assert sim.elevators["E1"].floor == "0"
        await wait_until(lambda: sim.elevators["E1"].state == "idle")
        sim.stick_elevator("E1", True)
        stuck = await robot.request("call_elevator", {"elevator": "E1", "floor": "2"}, timeout=15)
        assert stuck.type == "command_failed" and stuck.payload["target"] == "E1"
        assert "no progress for 3 s" in stuck.payload["reason"]
