"""A robot that must charge while the only door to the chargers is out of order: its charge is
not made and failed again and again (the fault soak's loop: hundreds of charge tasks a second
for as long as the door was out, backend/tasks/blocked.py), staff get one alert saying why,
and it goes to charge once the door works again.

Real server (Task Manager, closures, BuildingInterface polling the building simulator over
Modbus/TCP), a robot agent on a real WebSocket link (tests/robot/safety_rig.py).
"""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from tests.robot.safety_rig import fleet, one_door_site

pytestmark = pytest.mark.timeout(120)

STATIONS = {"home1", "home2", "home3"}


async def test_a_robot_that_cannot_reach_a_charger_waits_for_the_door_with_one_alert(
    tmp_path: Path,
) -> None:
    # The door's trouble lifts after 3 s (as a door seen working again would lift it).
    async with fleet(
        tmp_path, ["R1"], start={"R1": "west"}, site=one_door_site(), trouble_hold_s=3.0
    ) as f:
        f.building.jam_door("D0")
        # Its battery runs low: battery_low, it must charge (home1..3, behind D0).
        f.agents["R1"].bus.endpoint("test").publish("battery_level", {"level": 0.2})
        await f.wait_for(lambda: f.of("battery_low", robot="R1"))
        await f.wait_for(lambda: f.of("closures_changed"), timeout=40)
        assert f.of("closures_changed")[0].payload["nodes"] == ["door0"]
        f.building.jam_door("D0", False)  # repaired; the trouble lifts at the end of its hold
        await f.wait_for(lambda: f.states.get("R1", {}).get("node") in STATIONS, timeout=60)

        charges = {
            m.payload["task_id"]
            for m in f.of("task_assigned", robot="R1")
            if m.payload["net"] == "battery_charge"
        }
        failed = [
            m.payload
            for m in f.of("task_ended", robot="R1")
            if m.payload["task_id"] in charges and m.payload["outcome"] == "failed"
        ]
        # One charge failed at the door, then none until the door worked; the last one went.
        assert len(failed) <= 2, f"{len(failed)} charge tasks failed: {failed[:3]}..."
        assert len(charges) <= len(failed) + 1
        async with httpx.AsyncClient(base_url=f.server.url) as http:
            r = await http.get(
                "/api/alerts?include_acked=true",
                headers={"Authorization": f"Bearer {f.server.admin_token}"},
            )
        assert r.status_code == 200, r.text
        [alert] = [a for a in r.json() if a["kind"] == "charge_unreachable"]
        assert alert["subject"] == "R1" and alert["count"] == 1
        assert "cannot reach a charging station: door D0 out of order" in alert["message"]
        # Resolved when it reached the station.
        await f.wait_for(lambda: f.of("alert_resolved", kind="charge_unreachable", subject="R1"))
        task_failed = [m for m in f.of("alert_raised") if m.payload["kind"] == "task_failed"]
        assert len(task_failed) <= 2
        assert not f.checker.violations, f.checker.violations
