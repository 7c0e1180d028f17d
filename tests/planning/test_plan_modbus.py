"""The virtual plan's Modbus wire (``bench.plan_modbus``): the server's module client calling the
building simulator's module stores in-process answers as the Modbus/TCP client does, faults
included, and only the pollers made while it is active get it (docs/planning.md, "The virtual
run")."""

from __future__ import annotations

import asyncio

import pytest

from backend.building._modbus import ModuleClient, ModuleExceptionAnswer, ModuleUnreachable
from backend.building.poller import ModulePoller, Sample
from bench.plan_modbus import StoreClient, in_process_modbus
from building_sim.devices import DoorState
from building_sim.simulator import BuildingSimulator
from guidebot.site.building import PointKind
from guidebot.site.building_config import BuildingConfig
from guidebot.site.yamlio import load_site_file
from tests.planning.test_sim import DEMO


def _config() -> BuildingConfig:
    site = load_site_file(DEMO)
    return BuildingConfig(
        modules=site.modules, doors=site.doors, elevators=site.elevators, buttons=site.buttons
    )


async def _pair(building: BuildingSimulator, module: str) -> tuple[ModuleClient, StoreClient]:
    port = building.ports[module]
    wire = ModuleClient("127.0.0.1", port, unit_id=1, timeout_s=1.0)
    await wire.connect()
    store = StoreClient(building.servers[module], building.stores[module], unit_id=1, timeout_s=0.2)
    await store.connect()
    return wire, store


def test_the_store_client_answers_as_the_modbus_client_does() -> None:
    async def main() -> None:
        async with BuildingSimulator(_config(), port_zero=True) as building:
            wire, store = await _pair(building, "otb_ground")
            building.write(building.config.doors[0].is_open, 1)
            building.press("button_entrance", ms=10_000)
            for kind in PointKind:
                size = len(building.stores["otb_ground"].tables[kind])
                if size:
                    assert await store.read(kind, 0, size) == await wire.read(kind, 0, size)
            # A write reaches the simulated device (the door's open coil starts the door) and
            # reads back over the wire.
            await store.write(PointKind.coil, 2, 1)
            assert building.doors["door_gallery"].state != DoorState.closed
            assert await wire.read(PointKind.coil, 2, 1) == [1]
            # Past the end of a table: the module's exception answer, as on the wire.
            with pytest.raises(ModuleExceptionAnswer, match="illegal data address") as got:
                await store.read(PointKind.coil, 0, 99)
            with pytest.raises(ModuleExceptionAnswer) as again:
                await wire.read(PointKind.coil, 0, 99)
            assert got.value.code == again.value.code == 2
            with pytest.raises(Exception, match="read-only"):
                await store.write(PointKind.discrete_input, 1, 1)
            wire.close()

    asyncio.run(main())


def test_the_store_client_sees_the_simulators_faults() -> None:
    async def main() -> None:
        async with BuildingSimulator(_config(), port_zero=True) as building:
            _, store = await _pair(building, "otb_first")
            await building.set_fault("otb_first", "exception", code=4)
            with pytest.raises(ModuleExceptionAnswer, match="device failure"):
                await store.read(PointKind.discrete_input, 0, 16)
            await building.set_fault("otb_first", "slow", delay_ms=500)  # over its 0.2 s
            with pytest.raises(ModuleUnreachable, match="no answer"):
                await store.read(PointKind.discrete_input, 0, 16)
            assert not store.connected
            await building.set_fault("otb_first", "offline")
            with pytest.raises(ModuleUnreachable, match="cannot connect"):
                await store.connect()
            await building.set_fault("otb_first", "none")
            await store.connect()
            assert store.connected and await store.read(PointKind.coil, 1, 1) == [0]

    asyncio.run(main())


def test_pollers_made_while_it_is_active_read_the_simulator_in_process() -> None:
    async def main() -> tuple[list[Sample], type, type]:
        samples: list[Sample] = []
        sampled = asyncio.Event()

        def on_sample(_: str, sample: Sample, __: float) -> None:
            samples.append(sample)
            sampled.set()

        async with BuildingSimulator(_config(), port_zero=True) as building:
            module = building.bound_config().modules[0]
            building.write(building.config.doors[0].is_open, 1)
            with in_process_modbus(building):
                poller = ModulePoller(module, on_sample, lambda _: None)
            outside = ModulePoller(module, lambda *_: None, lambda _: None)
            poller.start()
            await sampled.wait()
            await poller.stop()
            return samples, type(poller.client), type(outside.client)

    samples, inside, outside = asyncio.run(main())
    assert inside is StoreClient and outside is ModuleClient
    first, bits = samples[0][PointKind.discrete_input]
    assert bits[2 - first] == 1  # door_hall_is_open, address 2
