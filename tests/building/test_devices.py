"""Simulated doors and elevators, driven over real Modbus/TCP like the BuildingInterface does."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from backend.building._modbus import ModuleClient
from building_sim.devices import IllegalTransition
from building_sim.simulator import BuildingSimulator, SimulatorError
from guidebot.site.building import PointKind
from guidebot.testing import wait_until


@pytest.fixture
async def m1(sim: BuildingSimulator) -> AsyncIterator[ModuleClient]:
    client = ModuleClient("127.0.0.1", sim.ports["M1"], unit_id=1, timeout_s=2)
    await client.connect()
    yield client
    client.close()


async def test_elevator_goes_on_in_its_direction_then_turns_back_and_reports_its_floor(
    sim: BuildingSimulator, m1: ModuleClient
) -> None:
    elevator = sim.elevators["E1"]
    await m1.write(PointKind.coil, 4, 1)  # call to floor "2"
    await wait_until(lambda: elevator.state == "moving")
    await m1.write(PointKind.coil, 2, 1)  # call to floor "0" just as it leaves it
    await wait_until(lambda: elevator.state == "door_open")
    assert elevator.floor == "2"
    assert await m1.read(PointKind.discrete_input, 2, 3) == [0, 0, 1]
    assert await m1.read(PointKind.input_register, 0, 1) == [2]
    assert await m1.read(PointKind.coil, 4, 1) == [0]  # the served call is cleared
    # After its door closes it goes back down for the other call.
    await wait_until(lambda: elevator.floor == "0" and elevator.state == "door_open")
    assert await m1.read(PointKind.discrete_input, 2, 3) == [1, 0, 0]
    assert elevator.arrivals == 2


async def test_door_closes_when_its_coil_is_cleared(
    sim: BuildingSimulator, m1: ModuleClient
) -> None:
    door = sim.doors["D1"]
    await m1.write(PointKind.coil, 1, 1)
    await wait_until(lambda: door.state == "open")
    await m1.write(PointKind.coil, 1, 0)
    assert door.state == "closing"
    assert await m1.read(PointKind.discrete_input, 1, 1) == [0]
    await wait_until(lambda: door.state == "closed")
    assert door.openings == 1


async def test_simulator_refuses_unknown_names_and_illegal_moves(sim: BuildingSimulator) -> None:
    with pytest.raises(SimulatorError, match="no button 'B9'"):
        sim.press("B9")
    with pytest.raises(SimulatorError, match="no module 'M9'"):
        await sim.set_fault("M9", "offline")
    with pytest.raises(ValueError, match="'melt' is not a valid FaultKind"):
        await sim.set_fault("M1", "melt")
    with pytest.raises(IllegalTransition, match="closed -> open not allowed"):
        sim.doors["D1"]._go(sim.doors["D1"].state.__class__("open"))


async def test_a_stuck_elevator_keeps_its_call_and_serves_it_once_freed(
    sim: BuildingSimulator, m1: ModuleClient
) -> None:
    import httpx

    from building_sim.control import control_app

    elevator = sim.elevators["E1"]
    transport = httpx.ASGITransport(app=control_app(sim))
    async with httpx.AsyncClient(transport=transport, base_url="http://sim") as http:
        r = await http.post("/elevators/E1/stuck", json={"stuck": True})
        assert r.status_code == 200, r.text
        await m1.write(PointKind.coil, 4, 1)  # call to floor "2": it never comes
        await wait_until(lambda: 2 in elevator.pending)
        assert elevator.state == "idle" and elevator.arrivals == 0
        assert (await http.get("/state")).json()["elevators"]["E1"]["stuck"] is True
        missing = await http.post("/elevators/E9/stuck", json={"stuck": True})
        assert missing.status_code == 404 and "no elevator 'E9'" in missing.text
        assert (await http.post("/elevators/E1/stuck", json={"stuck": False})).status_code == 200
    await wait_until(lambda: elevator.floor == "2" and elevator.state == "door_open")
    assert elevator.arrivals == 1
