"""Dispatch over real robot processes (issue 36): a tour handed over mid-way continues from the
visitor's stop with another robot, staff send a robot to charge from the console, and idle
robots take turns.

Real server (Task and Traffic Managers, BuildingInterface over Modbus/TCP), robot agents with
their touch screens on real WebSocket links, on the safety venue (tests/robot/safety_rig.py)
with a three-stop tour: hall, west, east (through the corridors).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.robot.safety_rig import Fleet, fleet, guides, safety_site, with_walk

pytestmark = pytest.mark.timeout(150)


async def post(f: Fleet, path: str, body: dict[str, Any]) -> dict[str, Any]:
    async with httpx.AsyncClient(base_url=f.server.url) as http:
        r = await http.post(
            path, json=body, headers={"Authorization": f"Bearer {f.server.admin_token}"}
        )
    assert r.status_code in (200, 201), r.text
    return dict(r.json())


async def get(f: Fleet, path: str) -> Any:
    async with httpx.AsyncClient(base_url=f.server.url) as http:
        r = await http.get(path, headers={"Authorization": f"Bearer {f.server.admin_token}"})
    assert r.status_code == 200, r.text
    return r.json()


def ended(f: Fleet, task_id: str) -> dict[str, Any] | None:
    found = f.of("task_ended", task_id=task_id)
    return found[-1].payload if found else None


async def test_a_robot_taken_out_mid_tour_hands_it_over_from_the_visitors_stop(
    tmp_path: Path,
) -> None:
    async with (
        fleet(
            tmp_path, ["R1", "R2"], site=with_walk(safety_site()), external=frozenset({"R1", "R2"})
        ) as f,
        guides(f, ["R1", "R2"]) as agents,
    ):
        task = await post(f, "/api/tasks", {"kind": "tour", "params": {"tour": "walk"}})
        task_id = task["id"]
        await f.wait_for(lambda: f.of("task_started", task_id=task_id, robot="R1"), 30)
        # R1 reaches the second stop with its visitor, and staff take it out of service.
        await f.wait_for(
            lambda: f.of("tour_progress", task_id=task_id, robot="R1", index=2), timeout=60
        )
        await post(f, "/api/robots/R1/service", {"out_of_service": True})
        # R2's screen says it continues the tour from stop 2, before it gets there.
        await f.wait_for(lambda: (agents["R2"].screen.task or {}).get("handover"), 20)
        assert agents["R2"].screen.task["handover"]["stop"] == 2
        told = [m.payload for m in f.of("task_event", task_id=task_id, robot="R2")]
        assert told[0]["handover"]["from_robot"] == "R1" and told[0]["handover"]["stop"] == 2
        assert told[0]["arrival_s"] is not None  # when R2 is at the visitor, on the panel
        await f.wait_for(lambda: ended(f, task_id) and ended(f, task_id)["robot"] == "R2", 90)
        assert ended(f, task_id)["outcome"] == "done"
        # R2 went to the visitor's stop (west), not to the start (hall), and went on from there.
        went = [
            (m.payload["index"], m.payload["poi"])
            for m in f.of("tour_progress", task_id=task_id, robot="R2")
            if m.payload["stage"] == "arrived"
        ]
        assert went == [(2, "p_west"), (3, "p_east")]
        status = await get(f, f"/api/tasks/{task_id}")
        assert status["state"] == "done"
        assert status["handover"]["robot"] == "R2" and status["handover"]["reason"]
        assert status["handover"]["arrived_after_s"] is not None
        history = [row["event"] for row in await get(f, f"/api/tasks/{task_id}/history")]
        assert "handover: R2 at the visitor's stop 2" in history


async def test_staff_send_a_robot_to_charge_from_the_console(tmp_path: Path) -> None:
    async with (
        fleet(
            tmp_path,
            ["R1", "R2"],
            site=with_walk(safety_site()),
            start={"R2": "west"},
            external=frozenset({"R1", "R2"}),
        ) as f,
        guides(f, ["R1", "R2"]),
    ):
        sent = await post(f, "/api/robots/R2/charge", {})
        # R1 stands on c1: R2 takes the nearest free station.
        assert sent["robot"] == "R2" and sent["station"] in ("c2", "c3")
        home = {"c2": "home2", "c3": "home3"}[sent["station"]]
        # It drives there and runs its charge net at the station (a bare simulated base has
        # no charger to dock to: tests/robot/test_e2e.py docks on RoboCAN hardware).
        await f.wait_for(
            lambda: (
                f.states["R2"].get("node") == home
                and f.states["R2"].get("task_id") == sent["task_id"]
                and "battery_charge" in f.states["R2"].get("nets", [])
            ),
            60,
        )
        logged = await get(f, "/api/events?kind=robot_sent_to_charge")
        assert [e["data"]["robot"] for e in logged["events"]] == ["R2"]


async def test_idle_robots_take_turns(tmp_path: Path) -> None:
    async with (
        fleet(
            tmp_path,
            ["R1", "R2", "R3"],
            site=with_walk(safety_site()),
            external=frozenset({"R1", "R2", "R3"}),
        ) as f,
        guides(f, ["R1", "R2", "R3"]),
    ):
        served = []
        for _ in range(3):
            task = await post(f, "/api/tasks", {"kind": "go_to_poi", "params": {"poi": "p_hall"}})
            await f.wait_for(lambda t=task["id"]: ended(f, t), 60)
            done = ended(f, task["id"])
            assert done is not None and done["outcome"] == "done"
            served.append(done["robot"])
        # The robot that just guided stands at the hall, nearest to the next visitor; the
        # others, a few metres further, have their turn.
        assert sorted(served) == ["R1", "R2", "R3"], served
        robots = {r["name"]: r for r in await get(f, "/api/robots")}
        assert all(robots[n]["touring_s"] > 0 for n in ("R1", "R2", "R3"))
