"""Where the elevator car is (``elevator_state``, backend/building/elevators.py), from the real
simulator over Modbus: its floor register from the start, then moving, then open at the floor
it was called to."""

from __future__ import annotations

import itertools

from backend.building.interface import BuildingInterface
from building_sim.simulator import BuildingSimulator
from guidebot.bus import Bus
from guidebot.testing import Recorder


async def test_the_car_is_followed_from_its_register_to_the_floor_it_was_called_to(
    hub: Bus, recorder: Recorder, sim: BuildingSimulator, interface: BuildingInterface
) -> None:
    first = sim.elevators["E1"].floor
    await recorder.wait("elevator_state", elevator="E1", floor=first, state="idle")
    robot = hub.endpoint("R1")
    reply = await robot.request("call_elevator", {"elevator": "E1", "floor": "2"}, timeout=15)
    assert reply.type == "elevator_in_position"
    states = [m.payload for m in recorder.of("elevator_state")]
    assert any(s["state"] == "moving" and s["calls"] == ["2"] for s in states), states
    await recorder.wait("elevator_state", floor="2", state="door_open", door_open=True)
    (now,) = interface.elevators.states()
    assert now.floor == "2"
    # Each state is published once, on its change: no repeats between polls.
    states = [m.payload for m in recorder.of("elevator_state")]
    assert all(a != b for a, b in itertools.pairwise(states))
