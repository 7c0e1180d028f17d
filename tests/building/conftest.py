"""A small building (two modules, a door, an elevator, two buttons) served by building_sim."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import pytest

from backend.building.interface import BuildingInterface
from building_sim.simulator import BuildingSimulator
from guidebot.bus import Bus
from guidebot.site.building_config import BuildingConfig, load_building
from guidebot.testing import Recorder, wait_until

TIME_SCALE = 20.0
PERIOD_MS = 50  # fast enough that a 300 ms press is always seen twice 200 ms apart


def site_dict(period_ms: int = PERIOD_MS) -> dict[str, Any]:
    return {
        "building": {
            "modules": [
                {
                    "id": "M1",
                    "port": 0,
                    "sampling_period_ms": period_ms,
                    "timeout_ms": 300,
                    "points": [
                        {"name": "b1", "address": 0, "kind": "discrete_input", "node": "hall"},
                        {"name": "d1_open", "address": 1, "kind": "discrete_input", "node": "d1"},
                        {"name": "e1_at_0", "address": 2, "kind": "discrete_input", "node": "e0"},
                        {"name": "e1_at_1", "address": 3, "kind": "discrete_input", "node": "e1"},
                        {"name": "e1_at_2", "address": 4, "kind": "discrete_input", "node": "e2"},
                        {"name": "b1_led", "address": 0, "kind": "coil"},
                        {"name": "d1_cmd", "address": 1, "kind": "coil"},
                        {"name": "e1_call_0", "address": 2, "kind": "coil"},
                        {"name": "e1_call_1", "address": 3, "kind": "coil"},
                        {"name": "e1_call_2", "address": 4, "kind": "coil"},
                        {"name": "E1_floor", "address": 0, "kind": "input_register"},
                    ],
                },
                {
                    "id": "M2",
                    "port": 0,
                    "sampling_period_ms": period_ms,
                    "timeout_ms": 300,
                    "points": [
                        {"name": "b2", "address": 0, "kind": "discrete_input", "node": "lab"},
                        {"name": "lamp", "address": 0, "kind": "coil"},
                    ],
                },
            ],
            "doors": [
                {
                    "id": "D1",
                    "node": "d1",
                    "open": {"module": "M1", "point": "d1_cmd"},
                    "is_open": {"module": "M1", "point": "d1_open"},
                    "open_time_s": 2.0,
                }
            ],
            "elevators": [
                {
                    "id": "E1",
                    "travel_time_s": 8.0,
                    "stops": [
                        {
                            "floor": str(i),
                            "node": f"e{i}",
                            "call": {"module": "M1", "point": f"e1_call_{i}"},
                            "in_position": {"module": "M1", "point": f"e1_at_{i}"},
                        }
                        for i in range(3)
                    ],
                }
            ],
            "buttons": [
                {
                    "id": "B1",
                    "input": {"module": "M1", "point": "b1"},
                    "led": {"module": "M1", "point": "b1_led"},
                    "node": "hall",
                    "task": {"kind": "tour", "params": {"tour": "main"}, "priority": 7},
                },
                {
                    "id": "B2",
                    "input": {"module": "M2", "point": "b2"},
                    "node": "lab",
                    "task": {"kind": "go_to_poi", "params": {"poi": "lab"}},
                },
            ],
        }
    }


@pytest.fixture
def building() -> BuildingConfig:
    return load_building(site_dict())


@pytest.fixture
async def sim(building: BuildingConfig) -> AsyncIterator[BuildingSimulator]:
    async with BuildingSimulator(
        building, time_scale=TIME_SCALE, port_zero=True, door_hold_s=20, elevator_hold_s=20
    ) as simulator:
        yield simulator


@pytest.fixture
def hub() -> Bus:
    return Bus()


@pytest.fixture
def recorder(hub: Bus) -> Recorder:
    return Recorder(
        hub.endpoint("recorder"),
        "building_*",
        "task_request",
        "door_*",
        "elevator_*",
        "command_failed",
    )


@pytest.fixture
async def interface(hub: Bus, sim: BuildingSimulator) -> AsyncIterator[BuildingInterface]:
    async with BuildingInterface(
        hub.endpoint("building"), sim.bound_config(), filter_ms=200, health_interval_s=1.0
    ) as bi:
        await wait_until(lambda: all(p.health.polls > 0 for p in bi.pollers.values()))
        yield bi
