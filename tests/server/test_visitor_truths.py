"""What a visitor is told is true (docs/visitor.md): while staff pause the fleet a queued
request is told the service is paused, with no wait to count down, and a real wait again once
they resume; a visit to one point says when its robot is there; each point of a task's history
has its own time. A real server and real robot agents (tests/server/test_visitor_eta.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from backend.tasks.model import TaskState
from tests.server.test_visitor_eta import PANEL, client, corridor, first

pytestmark = pytest.mark.timeout(120)


async def test_a_queued_request_is_told_the_fleet_is_paused_and_no_wait(tmp_path: Path) -> None:
    async with corridor(tmp_path) as c, client(c.server, PANEL) as http, client(c.server) as staff:
        manager = c.server.app.state.task_manager
        await c.until(lambda: manager.robots["R1"].online)
        running = (
            await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "long"}})
        ).json()
        await c.until(lambda: first(c.events, running["id"], "running") is not None)
        queued = (
            await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "short"}})
        ).json()
        assert queued["service"] == "busy" and queued["eta_s"] > 0
        told = len(c.events)
        assert (
            await staff.post("/api/fleet/pause", json={"reason": "cleaning"})
        ).status_code == 200

        def paused_news() -> bool:
            return any(
                e.payload["task_id"] == queued["id"] and e.payload.get("service") == "paused"
                for e in c.events[told:]
            )

        await c.until(paused_news)
        news = next(
            e
            for e in c.events[told:]
            if e.payload["task_id"] == queued["id"] and e.payload.get("service") == "paused"
        )
        assert news.payload["eta_s"] is None and news.payload["arrival_s"] is None
        mine = (await http.get(f"/api/tasks/{queued['id']}")).json()
        assert mine["service"] == "paused" and mine["eta_s"] is None
        menu = (await http.get("/api/visitor")).json()
        assert menu["service"] == "paused"
        assert menu["tours"][0]["estimate"]["service"] == "paused"
        assert menu["tours"][0]["estimate"]["eta_s"] is None
        # The running tour goes on and ends; the queued one still waits, told paused.
        await c.until(lambda: first(c.events, running["id"], "done") is not None)
        assert manager.tasks[queued["id"]].state is TaskState.QUEUED
        assert (await http.get(f"/api/tasks/{queued['id']}")).json()["service"] == "paused"
        resumed = len(c.events)
        assert (await staff.post("/api/fleet/resume")).status_code == 200
        await c.until(
            lambda: any(
                e.payload["task_id"] == queued["id"] and e.payload.get("service") != "paused"
                for e in c.events[resumed:]
            )
        )
        mine = (await http.get(f"/api/tasks/{queued['id']}")).json()
        assert mine["service"] != "paused" and mine["eta_s"] is not None


async def test_a_visit_to_one_point_says_when_its_robot_is_there(tmp_path: Path) -> None:
    async with corridor(tmp_path) as c, client(c.server, PANEL) as http, client(c.server) as staff:
        manager = c.server.app.state.task_manager
        await c.until(lambda: manager.robots["R1"].online)
        r = await http.post("/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "p2"}})
        task_id = r.json()["id"]
        await c.until(lambda: first(c.events, task_id, "done") is not None)
        arrived = [
            e.payload["progress"]
            for e in c.events
            if e.payload["task_id"] == task_id
            and e.payload["state"] == "running"
            and (e.payload.get("progress") or {}).get("stage") == "arrived"
        ]
        assert arrived, "no task_event says the robot is at the point"
        assert arrived[0]["index"] == 1 and arrived[0]["total"] == 1
        assert arrived[0]["poi"] == "p2" and arrived[0]["name"] in ("Coins", None)
        history = (await staff.get(f"/api/tasks/{task_id}/history")).json()
        assert "point 1/1 arrived" in [row["event"] for row in history]


async def test_each_point_of_a_tours_history_has_its_own_time(tmp_path: Path) -> None:
    async with corridor(tmp_path) as c, client(c.server) as http:
        manager = c.server.app.state.task_manager
        await c.until(lambda: manager.robots["R1"].online)
        r = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "long"}})
        task_id = r.json()["id"]
        await c.until(lambda: first(c.events, task_id, "done") is not None)
        history = (await http.get(f"/api/tasks/{task_id}/history")).json()
        points = [row for row in history if row["event"].startswith("point ")]
        assert len(points) == 6
        times = [row["at"] for row in points]
        assert times == sorted(times)
        assert len(set(times)) == len(times), f"points share a time: {points}"
        started = next(row["at"] for row in history if row["state"] == "running")
        assert times[0] > started
