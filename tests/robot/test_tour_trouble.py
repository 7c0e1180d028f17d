"""A tour whose way to its next stops a door jams for a moment waits for it, and visits them.

In the 30-minute fault soaks a door jam of a few seconds made tours skip every stop behind it:
the robot's navigation failed ``closed`` at once while the jam's trouble closure was in force,
and give_tour skipped the stop. A stop only trouble cuts off is waited for a bounded while
(give_tour's ``trouble_wait_s``, robot_agent/navigation.py) before it is skipped.

Real server (Task Manager, closures, BuildingInterface polling the building simulator over
Modbus/TCP), a robot agent with its touch screen (a visitor who always says yes) on a real
WebSocket link, on the safety venue's ground floor (tests/robot/safety_rig.py): the tour goes
hall, then west and east, which only door D0 leads to.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.robot.safety_rig import WALK_STOPS, Fleet, fleet, guides, one_door_site, with_walk

pytestmark = pytest.mark.timeout(120)


async def call(f: Fleet, method: str, path: str, body: dict[str, Any] | None = None) -> Any:
    async with httpx.AsyncClient(base_url=f.server.url) as http:
        r = await http.request(
            method, path, json=body, headers={"Authorization": f"Bearer {f.server.admin_token}"}
        )
    assert r.status_code in (200, 201, 204), r.text
    return r.json() if r.content else None


async def test_a_tour_waits_for_a_door_jammed_a_moment_and_visits_the_stops_behind_it(
    tmp_path: Path,
) -> None:
    # The trouble hold outlasts the jam (the default is 120 s): only staff reopening the door,
    # the door seen working or the hold's end lifts it; here staff reopen it once it works.
    async with (
        fleet(tmp_path, ["R1"], site=with_walk(one_door_site()), external=frozenset({"R1"})) as f,
        guides(f, ["R1"]),
    ):
        f.building.jam_door("D0")
        task = await call(f, "POST", "/api/tasks", {"kind": "tour", "params": {"tour": "walk"}})
        task_id = task["id"]
        # On its way to the second stop the door does not open: trouble closes it, and the
        # server answers the robot's next plan that only the broken door leads there.
        await f.wait_for(lambda: f.of("path", closed=True), 60)
        assert f.of("path", closed=True)[0].payload["reason"] == "door D0 out of order"
        f.building.jam_door("D0", False)  # a jam of a moment: it works again
        await call(f, "DELETE", "/api/closures/trouble-door-D0")
        await f.wait_for(lambda: f.of("task_ended", task_id=task_id), 90)
        assert f.of("task_ended", task_id=task_id)[0].payload["outcome"] == "done"
        progress = [(m.payload["stage"], m.payload["poi"]) for m in f.of("tour_progress")]
        assert not [poi for stage, poi in progress if stage == "skipped"], progress
        arrived = [poi for stage, poi in progress if stage == "arrived"]
        assert arrived == WALK_STOPS, progress
        assert not f.checker.violations, f.checker.violations
