"""The wait told to visitors: a real server, real robot agents (bare simulated bases, timed
speech, 40x robot time) in the corridor museum (bench/eta.py) and a queue of tours. Told waits
grow with the line; each point reached and explained lands in the task's history; "busy" and
"unavailable" are told apart. How close told waits come to real ones is a wall-clock figure,
measured by ``guidebot bench eta`` (docs/visitor.md), not bounded here."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.eta import PANEL, client, corridor, first, queue_once

pytestmark = pytest.mark.timeout(120)


async def test_a_queue_is_told_longer_waits_further_back_and_the_tour_learned_from_is_in_history(
    tmp_path: Path,
) -> None:
    run = await queue_once(tmp_path)
    ids = list(run.told)
    # The first may start at once (the robot is free); the others waited for tours, and were
    # told so: the third, behind a long and a short tour, longer than the second.
    assert all(run.waits[t] > 0.5 for t in ids[1:]), run.waits
    assert run.told[ids[2]] > run.told[ids[1]] > 0  # no more "everyone waits 180 s"
    assert "point 1/3 arrived" in run.warm_history and "point 3/3 explained" in run.warm_history
    assert run.menu_duration_s > 0


async def test_a_running_tour_reports_its_progress_live(tmp_path: Path) -> None:
    async with corridor(tmp_path) as c, client(c.server, PANEL) as http:
        events = c.events
        await c.until(lambda: c.server.app.state.task_manager.robots["R1"].online)
        r = await http.post(
            "/api/tasks", json={"kind": "tour", "params": {"tour": "short", "lang": "es"}}
        )
        task_id = r.json()["id"]
        await c.until(lambda: first(events, task_id, "done") is not None)
        progress = [
            (e.payload["progress"]["index"], e.payload["progress"]["stage"])
            for e in events
            if e.payload["task_id"] == task_id
            and e.payload.get("progress")
            and e.payload["state"] == "running"
        ]
        # The robot seen on its way again after stop 1 is news of the same stop (``going``,
        # tests/server/test_visitor_waits.py), when a robot_state came on the way.
        stages = [p for i, p in enumerate(progress) if i == 0 or p != progress[i - 1]]
        assert stages[-4:] == [(1, "arrived"), (1, "explained"), (2, "arrived"), (2, "explained")]
        # The end keeps where the tour got to (the visitor's page says it).
        end = first(events, task_id, "done")
        assert end is not None and end.payload["progress"]["index"] == 2
        remaining = [
            e.payload["remaining_s"]
            for e in events
            if e.payload["task_id"] == task_id and e.payload["state"] == "running"
        ]
        assert remaining and remaining[-1] < remaining[0]
        # Spanish where the site has it, the default language (and its voice) where not.
        sent = c.server.app.state.task_manager.tasks[task_id].assigned_params
        assert sent["lang"] == "es"
        assert [(p["text"], p["lang"]) for p in sent["points"]] == [
            ("Silver coins of three kings.", "en"),
            ("El primer mapa del valle.", "es"),
        ]


async def test_busy_is_told_apart_from_no_robot_in_service(tmp_path: Path) -> None:
    async with corridor(tmp_path) as c, client(c.server, PANEL) as http:
        manager = c.server.app.state.task_manager
        await c.until(lambda: manager.robots["R1"].online)
        assert (await http.get("/api/visitor")).json()["service"] == "available"
        r = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "long"}})
        await c.until(lambda: first(c.events, r.json()["id"], "running") is not None)
        menu = (await http.get("/api/visitor?lang=es")).json()
        assert menu["service"] == "busy" and menu["lang"] == "es"
        assert menu["tours"][0]["estimate"]["service"] == "busy"
        assert menu["tours"][0]["estimate"]["eta_s"] > 0
        queued = (
            await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "short"}})
        ).json()
        assert queued["service"] == "busy" and queued["queue_position"] == 1
        # The only robot goes off the network: nobody can serve the queued tour any more.
        await c.agents["R1"].stop()
        await c.until(lambda: not manager.robots["R1"].online)
        mine = (await http.get(f"/api/tasks/{queued['id']}")).json()
        assert mine["service"] == "unavailable" and mine["eta_s"] is None
        assert (await http.get("/api/visitor")).json()["service"] == "unavailable"


async def test_a_language_not_offered_is_refused_and_a_tour_deleted_meanwhile_is_withdrawn(
    tmp_path: Path,
) -> None:
    async with corridor(tmp_path, robots=0) as c, client(c.server, PANEL) as http:
        server = c.server
        r = await http.post(
            "/api/tasks", json={"kind": "tour", "params": {"tour": "long", "lang": "fr"}}
        )
        assert r.status_code == 422 and "not offered" in r.text
        queued = (
            await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "short"}})
        ).json()
        assert queued["service"] == "unavailable"
        async with client(server) as admin:
            assert (await admin.delete("/api/tours/short")).status_code == 204
        gone = (await http.get(f"/api/tasks/{queued['id']}")).json()
        assert gone["state"] == "cancelled" and gone["service"] == "withdrawn"
