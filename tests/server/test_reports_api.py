"""The reports over REST, from the event log of a real run: a visitor's tour on a running
server with a robot on the hub, then the figures, CSV and the refusals (docs/reports.md)."""

from __future__ import annotations

import csv
import datetime as dt
import io
from pathlib import Path

from sqlalchemy import select

from backend.db.models import EventRow
from backend.testing import RunningServer, running_server

from .conftest import OPERATOR_TOKEN, PANEL_TOKEN, server_settings
from .test_api import GROUND, Http, eventually, robot


async def test_a_tour_run_on_the_server_is_in_the_days_report(
    server: RunningServer, http: Http
) -> None:
    panel, staff = http(PANEL_TOKEN), http(OPERATOR_TOKEN)
    tm = server.app.state.task_manager
    async with robot(server, "R1", "hall") as r1:
        task = (await panel.post("/api/tasks", json=GROUND)).json()
        await r1.next_order("give_tour")
        r1.task_id = task["id"]
        r1.client.publish("task_started", {"task_id": task["id"], "robot": "R1"})
        await eventually(lambda: tm.get(task["id"]).state == "running")
        for stage in ("arrived", "explained"):
            progress = {"index": 1, "total": 5, "poi": "welcome", "stage": stage}
            r1.client.publish("tour_progress", {"task_id": task["id"], "robot": "R1", **progress})
        await r1.client.sync()
        # The visitors answered "no" after the first stop: the robot ends the tour done.
        r1.client.publish("task_ended", {"task_id": task["id"], "robot": "R1", "outcome": "done"})
        await eventually(lambda: tm.get(task["id"]).state == "done")

    hour = dt.datetime.now(dt.UTC).replace(minute=0, second=0, microsecond=0)
    around = {
        "start": (hour - dt.timedelta(hours=1)).isoformat(),
        "end": (hour + dt.timedelta(hours=2)).isoformat(),
    }
    answer = await staff.get("/api/reports", params=around)
    assert answer.status_code == 200, answer.text
    report = answer.json()
    assert report["period"]["bin"] == "hour" and report["period"]["tz"] == "UTC"
    tours = {"kind": "tour", "requested": 1, "done": 1, "failed": 0, "cancelled": 0}
    assert tours in report["tasks"]["by_kind"]  # besides the Task Manager's own charges
    assert report["waits"]["wait_s"]["count"] == 1
    assert report["waits"]["tour_length_s"]["count"] == 1
    assert (report["following"]["tours"], report["following"]["stopped"]) == (1, 1)
    assert {"by": "stop", "name": "welcome", "tours": 1, "stopped": 1, "share": 1.0} in report[
        "following"
    ]["rows"]
    assert report["stops"]["rows"] == [{"stop": "welcome", "listened": 1}]
    [r1_row] = [r for r in report["robots"]["rows"] if r["robot"] == "R1"]
    assert r1_row["touring_s"] >= 0 and r1_row["offline_s"] >= 0

    # The same hours to play back: the tour's start among them.
    played = (await staff.get("/api/reports/replay", params=around)).json()
    assert any(
        e["kind"] == "task_started" and e["data"]["task_id"] == task["id"] for e in played["events"]
    )

    # One figure as CSV: a row per hour, with a header.
    exported = await staff.get("/api/reports/tasks", params={**around, "format": "csv"})
    assert exported.status_code == 200
    assert exported.headers["content-type"].startswith("text/csv")
    name = f"guidebot-tasks-{around['start'][:10]}.csv"
    assert name in exported.headers["content-disposition"]
    rows = list(csv.DictReader(io.StringIO(exported.text)))
    assert len(rows) == 3
    assert list(rows[0]) == ["start", "requested", "done", "failed", "cancelled"]
    assert sum(int(r["requested"]) for r in rows[:2]) == 1
    # The hour to come has no counts yet (blank), not zero tours.
    assert rows[2]["requested"] == rows[2]["done"] == ""
    later = report["waits"]["rows"][2]
    assert later["waits"] is None and later["tours_done"] is None
    assert report["tasks"]["rows"][2]["requested"] is None


async def test_bad_periods_are_422_with_the_reason_and_only_staff_read(http: Http) -> None:
    staff, panel = http(OPERATOR_TOKEN), http(PANEL_TOKEN)
    for params, says in (
        ({}, "give one period"),
        ({"start": "2026-07-14T10:00", "end": "2026-07-14T09:00"}, "ends before it starts"),
        ({"day": "2026-02-30"}, "is not a date"),
        ({"start": "2024-01-01", "end": "2026-01-01"}, "longer than 400 days"),
        ({"day": "2026-07-14", "tz": "Nowhere/Town"}, "unknown time zone"),
    ):
        answer = await staff.get("/api/reports/waits", params=params)
        assert answer.status_code == 422, params
        assert says in answer.json()["detail"], answer.json()
    assert (
        await staff.get("/api/reports/weather", params={"day": "2026-07-14"})
    ).status_code == 422
    long = await staff.get("/api/reports/replay", params={"week": "2026-07-13"})
    assert long.status_code == 422 and "at most 24 hours" in long.json()["detail"]
    csv_only = {"day": "2026-07-14", "format": "pdf"}
    assert (await staff.get("/api/reports/tasks", params=csv_only)).status_code == 422
    assert (await panel.get("/api/reports", params={"day": "2026-07-14"})).status_code == 403
    assert (await http(None).get("/api/reports", params={"day": "2026-07-14"})).status_code == 401


async def test_a_clean_stop_is_logged_between_two_server_lives(tmp_path: Path) -> None:
    """A server stopped cleanly writes ``server_stopped`` last, so the reports count the time
    until the next start as the server down (docs/reports.md, the ``robots`` figure)."""
    settings = server_settings(tmp_path)
    async with running_server(settings):
        pass
    async with running_server(settings) as srv:
        store = srv.app.state.store
        async with store.sessionmaker() as session:
            rows = await session.execute(select(EventRow.kind).order_by(EventRow.id))
            kinds = [k for (k,) in rows if k.startswith("server_")]
    assert kinds == ["server_started", "server_stopped", "server_started"]
