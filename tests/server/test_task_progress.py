"""A finished tour keeps its last progress in ``GET /api/tasks/{id}``: how far it went and the
stops it skipped (docs/server.md, "Task life cycle"; docs/protocol.md, "Skipped stops")."""

from __future__ import annotations

from typing import Any

from backend.testing import RunningServer

from .conftest import OPERATOR_TOKEN, PANEL_TOKEN
from .test_api import GROUND, Http, eventually, robot

SKIP_REASON = "gallery ga closed: cleaning"


async def test_a_finished_tour_keeps_its_progress_and_its_skipped_stops(
    server: RunningServer, http: Http
) -> None:
    """The status of a tour that ended said ``progress: null``: a visitor's page that reloaded
    after the end lost the stops it had been told were skipped, and why."""
    panel, staff = http(PANEL_TOKEN), http(OPERATOR_TOKEN)
    tm = server.app.state.task_manager
    async with robot(server, "R1", "hall") as r1:
        task = (await panel.post("/api/tasks", json=GROUND)).json()
        await r1.next_order("give_tour")
        r1.task_id = task["id"]
        r1.client.publish("task_started", {"task_id": task["id"], "robot": "R1"})
        await eventually(lambda: tm.get(task["id"]).state == "running")

        def report(index: int, poi: str, stage: str, reason: str = "") -> None:
            told: dict[str, Any] = {"index": index, "total": 5, "poi": poi, "stage": stage}
            if reason:
                told["reason"] = reason
            r1.client.publish("tour_progress", {"task_id": task["id"], "robot": "R1", **told})

        report(1, "welcome", "arrived")
        report(1, "welcome", "explained")
        report(2, "mosaics", "skipped", SKIP_REASON)
        report(3, "amphorae", "arrived")
        report(3, "amphorae", "explained")
        await r1.client.sync()
        await eventually(
            lambda: (tm.status(tm.get(task["id"]))["progress"] or {}).get("index") == 3
        )
        running = (await panel.get(f"/api/tasks/{task['id']}")).json()["progress"]
        # The visitors answered "no" after the third stop: the robot ends the tour done.
        r1.client.publish("task_ended", {"task_id": task["id"], "robot": "R1", "outcome": "done"})
        await eventually(lambda: tm.get(task["id"]).state == "done")

    skipped = [{"index": 2, "poi": "mosaics", "name": "Roman mosaics", "reason": SKIP_REASON}]
    assert running["skipped"] == skipped
    for reader in (panel, staff):
        done = (await reader.get(f"/api/tasks/{task['id']}")).json()
        assert done["state"] == "done"
        assert done["progress"] == running
        assert (done["progress"]["index"], done["progress"]["stage"]) == (3, "explained")
