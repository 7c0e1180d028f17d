"""The bare simulated robot's battery (``robot_agent.sim_base.SimulatedBattery``), which follows
the robot's clock and so the virtual plan's (docs/planning.md, "The virtual run"): it drains at
RoboCAN's simulated battery's rates, charges on the dock, and the robot's battery monitor ends
a charge with ``charged``."""

from __future__ import annotations

import asyncio

import pytest

from backend.planning.vtime import virtual_time
from bench.plan_virtual import EPOCH
from guidebot.bus import Bus
from guidebot.messages import Message
from robot_agent.battery import BatteryMonitor
from robot_agent.clock import Clock
from robot_agent.hardware import BareSimulation
from robot_agent.robocan.sim.battery import SimBattery


def test_a_bare_battery_drains_standing_and_moving_at_the_simulated_modules_rates() -> None:
    async def main() -> tuple[float, float, list[dict]]:
        bus = Bus()
        levels: list[dict] = []
        bus.endpoint("probe").subscribe("battery_level", lambda m: levels.append(m.payload))
        hardware = BareSimulation(bus.endpoint("base"), Clock(), battery=1.0)
        async with hardware:
            await asyncio.sleep(600.0)  # ten minutes standing
            standing = levels[-1]["level"]
            bus.endpoint("nav").publish("set_velocity", {"v": 0.5, "w": 0.0})
            await asyncio.sleep(600.0)  # ten minutes driving
            return standing, levels[-1]["level"], levels

    standing, moving, levels = virtual_time(main(), epoch=EPOCH)
    assert standing == pytest.approx(1.0 - 600 * SimBattery.IDLE_DRAIN, abs=1e-4)
    # Ten minutes at the moving rate (the first second: accelerating from standing).
    assert standing - moving == pytest.approx(600 * SimBattery.MOVING_DRAIN, abs=2e-4)
    # Reported every robot second, as the battery module publishes.
    assert 1199 <= len(levels) <= 1202
    assert levels[-1]["voltage"] == pytest.approx(22.0 + 4.0 * moving)


def test_a_docked_bare_robot_charges_to_full_then_the_monitor_ends_the_charge() -> None:
    async def main() -> tuple[list[Message], list[Message], float]:
        bus = Bus()
        charged: list[Message] = []
        switched: list[Message] = []
        probe = bus.endpoint("probe")
        probe.subscribe("charged", charged.append)
        probe.subscribe("set_charging", switched.append)
        hardware = BareSimulation(bus.endpoint("base"), Clock(), battery=0.9)
        monitor = BatteryMonitor(bus.endpoint("battery"), "R1")
        async with hardware, monitor:
            await asyncio.sleep(5.0)
            bus.endpoint("navigation").publish("docked", {"station": "dock1", "node": "dock1"})
            await asyncio.sleep(900.0)
            assert hardware.battery is not None
            return charged, switched, hardware.battery.level

    charged, switched, level = virtual_time(main(), epoch=EPOCH)
    # From 0.9 to the monitor's "full" (0.95) at one full charge an hour: 3 minutes; then the
    # charger opens once (no report heard in the middle of the monitor's own undocking).
    assert len(charged) == 1 and charged[0].payload["level"] == pytest.approx(0.95, abs=1e-3)
    assert [m.payload["on"] for m in switched] == [True, False]
    # After the charge the battery stands again and drains.
    assert level < 0.95


def test_a_bad_start_level_is_refused() -> None:
    with pytest.raises(ValueError, match=r"within 0\.\.1"):
        BareSimulation(Bus().endpoint("base"), Clock(), battery=1.5)
