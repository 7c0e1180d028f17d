"""Bookings (backend/bookings) over a real server: book, list, move, cancel, history, the
refusals with their reasons, the next public tours, and an occurrence started exactly once
across restarts (docs/server.md, "Bookings")."""

from __future__ import annotations

import asyncio
import datetime as dt
import time
from pathlib import Path
from typing import Any

import httpx
from click.testing import CliRunner, Result

from backend.bookings.cli import bookings as bookings_cli
from backend.bookings.schedule import requester_of
from backend.testing import RunningServer, running_server
from guidebot.testing import wait_until

from .conftest import OPERATOR_TOKEN, PANEL_TOKEN, PERSON_TOKENS, server_settings
from .helpers import RobotStub

VIEWER_TOKEN = PERSON_TOKENS[next(r for r in PERSON_TOKENS if r.value == "viewer")]


def tomorrow(hh_mm: str = "14:00") -> str:
    day = dt.datetime.now(dt.UTC).date() + dt.timedelta(days=1)
    return f"{day.isoformat()}T{hh_mm}"


def client(srv: RunningServer, token: str) -> httpx.AsyncClient:
    return httpx.AsyncClient(
        base_url=srv.url, headers={"Authorization": f"Bearer {token}"}, timeout=10
    )


def spanish(start: str, **extra: Any) -> dict[str, Any]:
    return {"tour": "highlights", "start": start, "lang": "es", "group_size": 25, **extra}


async def test_staff_book_list_move_and_cancel_and_the_history_says_who(
    server: RunningServer,
) -> None:
    async with client(server, OPERATOR_TOKEN) as http:
        made = await http.post("/api/bookings", json=spanish(tomorrow(), note="school"))
        assert made.status_code == 201, made.text
        booking = made.json()
        assert booking["meeting_point"] == "mosaics"  # the tour's first stop by default
        assert booking["meeting_point_name"] and booking["tz"] == "UTC"
        assert booking["status"] == "booked" and booking["created_by"] == "operator-1"
        day = tomorrow()[:10]
        listed = (await http.get(f"/api/bookings?start={day}")).json()
        assert [o["id"] for o in listed["occurrences"]] == [booking["id"]]
        assert listed["occurrences"][0]["local"] == tomorrow()

        moved = await http.post(
            f"/api/bookings/{booking['id']}/move",
            json={"start": tomorrow("15:30"), "meeting_point": "welcome"},
        )
        assert moved.status_code == 200, moved.text
        assert moved.json()["start"] == tomorrow("15:30")
        cancelled = await http.post(f"/api/bookings/{booking['id']}/cancel", json={})
        assert cancelled.json()["status"] == "cancelled"
        again = await http.post(f"/api/bookings/{booking['id']}/cancel", json={})
        assert again.status_code == 422 and "already cancelled" in again.json()["detail"]
        assert (await http.get(f"/api/bookings?start={day}")).json()["occurrences"] == []

        history = (await http.get(f"/api/bookings/{booking['id']}/history")).json()
        assert [(h["action"], h["by"]) for h in history] == [
            ("created", "operator-1"),
            ("moved", "operator-1"),
            ("cancelled", "operator-1"),
        ]
        assert history[1]["detail"]["start"] == {"from": tomorrow(), "to": tomorrow("15:30")}
        assert (await http.get("/api/bookings/nope/history")).status_code == 404


async def test_bad_bookings_are_refused_with_the_reason(server: RunningServer) -> None:
    yesterday = (dt.datetime.now(dt.UTC) - dt.timedelta(days=1)).strftime("%Y-%m-%dT%H:%M")
    cases = [
        (spanish(yesterday), "in the past"),
        ({**spanish(tomorrow()), "tour": "nope"}, "unknown tour 'nope'"),
        ({**spanish(tomorrow()), "lang": "fr"}, "language 'fr' not offered"),
        ({**spanish(tomorrow()), "meeting_point": "nope"}, "unknown meeting point"),
        ({**spanish(tomorrow()), "poi": "sword"}, "either tour"),
        (
            {**spanish(tomorrow()), "recurrence": {"every": "daily", "until": "2000-01-01"}},
            "before the first date",
        ),
    ]
    async with client(server, OPERATOR_TOKEN) as http:
        for body, words in cases:
            answer = await http.post("/api/bookings", json=body)
            assert answer.status_code == 422, body
            assert words in str(answer.json()["detail"]), answer.json()
        for body in (
            {**spanish(tomorrow()), "group_size": 0},
            {**spanish(tomorrow()), "group_size": "25"},
            {**spanish(tomorrow()), "group_size": True},
            {**spanish(tomorrow()), "colour": "red"},
            {**spanish("tomorrow at two")},
        ):
            answer = await http.post("/api/bookings", json=body)
            assert answer.status_code == 422, body
        # A listing's dates: one that looks like a date but is none, one past the calendar.
        for query, words in (
            ("start=7797-05-00", "start='7797-05-00' is not a date"),
            ("start=2026-11-01&end=9999-12-31", "end='9999-12-31' is out of range"),
        ):
            answer = await http.get(f"/api/bookings?{query}")
            assert answer.status_code == 422 and words in answer.json()["detail"], answer.text
        far = await http.post("/api/bookings", json=spanish("9999-12-31T14:00"))
        assert far.status_code == 422 and "out of range" in far.json()["detail"], far.text
        # The demo fleet has three robots: a fourth booking at once is refused.
        for _ in range(3):
            assert (await http.post("/api/bookings", json=spanish(tomorrow()))).status_code == 201
        fourth = await http.post("/api/bookings", json=spanish(tomorrow("14:01")))
        assert fourth.status_code == 422
        assert "4 bookings at once" in fourth.json()["detail"]
        assert "3 robot(s) in service" in fourth.json()["detail"]
        later = await http.post("/api/bookings", json=spanish(tomorrow("18:00")))
        assert later.status_code == 201


async def test_viewers_read_bookings_and_panels_see_the_next_public_tours_in_their_language(
    lenient: RunningServer,
) -> None:
    start = (dt.datetime.now(dt.UTC) + dt.timedelta(minutes=30)).strftime("%Y-%m-%dT%H:%M")
    if start[:10] != dt.datetime.now(dt.UTC).date().isoformat():
        start = tomorrow("00:10")  # near midnight: "today" is tomorrow's list
    async with client(lenient, OPERATOR_TOKEN) as http:
        made = (await http.post("/api/bookings", json=spanish(start))).json()
        private = spanish(start, public=False, tour="ground")
        assert (await http.post("/api/bookings", json=private)).status_code == 201
    async with client(lenient, VIEWER_TOKEN) as viewer:
        assert (await viewer.get(f"/api/bookings/{made['id']}")).status_code == 200
        refused = await viewer.post("/api/bookings", json=spanish(tomorrow()))
        assert refused.status_code == 403
    async with client(lenient, PANEL_TOKEN) as panel:
        assert (await panel.get("/api/bookings")).status_code == 403
        if start.startswith(dt.datetime.now(dt.UTC).date().isoformat()):
            shown = (await panel.get("/api/bookings/next?lang=de")).json()
            assert [t["name"] for t in shown["tours"]] == ["Das Wichtigste"]
            assert shown["tours"][0]["time"] == start[11:16]
            assert shown["tours"][0]["lang"] == "es"


async def test_a_recurring_series_skips_its_exceptions_and_one_date_can_be_cancelled(
    server: RunningServer,
) -> None:
    first = dt.datetime.now(dt.UTC).date() + dt.timedelta(days=1)
    day = [(first + dt.timedelta(days=i)).isoformat() for i in range(8)]
    body = spanish(
        f"{day[0]}T11:00",
        recurrence={"every": "daily", "until": day[6], "except_dates": [day[2]]},
    )
    async with client(server, OPERATOR_TOKEN) as http:
        made = (await http.post("/api/bookings", json=body)).json()
        listed = (await http.get(f"/api/bookings?start={day[0]}&end={day[7]}")).json()
        dates = [o["local"][:10] for o in listed["occurrences"]]
        assert dates == [day[0], day[1], day[3], day[4], day[5], day[6]]
        one = await http.post(
            f"/api/bookings/{made['id']}/cancel", json={"occurrence": day[4], "reason": "closed"}
        )
        assert one.status_code == 200, one.text
        listed = (await http.get(f"/api/bookings?start={day[0]}&end={day[7]}")).json()
        assert day[4] not in [o["local"][:10] for o in listed["occurrences"]]
        wrong = await http.post(f"/api/bookings/{made['id']}/cancel", json={"occurrence": day[7]})
        assert wrong.status_code == 422 and "no occurrence" in wrong.json()["detail"]
        weekly = spanish(f"{day[0]}T16:00", recurrence={"every": "weekly", "days": ["mon", "thu"]})
        made = (await http.post("/api/bookings", json=weekly)).json()
        listed = (await http.get(f"/api/bookings?start={day[0]}&end={day[7]}")).json()
        weekdays = {
            dt.date.fromisoformat(o["local"][:10]).weekday()
            for o in listed["occurrences"]
            if o["id"] == made["id"]
        }
        assert weekdays == {0, 3}


async def _book_soon(srv: RunningServer) -> dict[str, Any]:
    async with client(srv, OPERATOR_TOKEN) as http:
        made = await http.post("/api/bookings", json=spanish(tomorrow("10:00")))
        assert made.status_code == 201, made.text
        return dict(made.json())


def _at(booking: dict[str, Any]) -> float:
    return dt.datetime.fromisoformat(booking["start"]).replace(tzinfo=dt.UTC).timestamp()


def _tasks_of(srv: RunningServer, booking: dict[str, Any]) -> list[Any]:
    requester = f"booking:{booking['id']}@{int(_at(booking))}"
    return [t for t in srv.app.state.task_manager.tasks.values() if t.requester == requester]


async def test_an_occurrence_is_started_once_across_restarts_just_before_and_after_its_time(
    tmp_path: Path,
) -> None:
    settings = server_settings(tmp_path)
    async with running_server(settings) as srv:
        booking = await _book_soon(srv)
        await srv.app.state.booking_scheduler.step(_at(booking) - 60)
        await srv.app.state.booking_scheduler.step(_at(booking) - 1)
        assert _tasks_of(srv, booking) == []  # not before its time; restarted just before
    async with running_server(settings) as srv:
        await srv.app.state.booking_scheduler.step(_at(booking) + 1)
        [task] = _tasks_of(srv, booking)
        assert task.priority == 50 and task.params["lang"] == "es"
    async with running_server(settings) as srv:  # restarted just after: not started again
        await srv.app.state.booking_scheduler.step(_at(booking) + 2)
        assert [t.id for t in _tasks_of(srv, booking)] == [task.id]
        async with client(srv, OPERATOR_TOKEN) as http:
            history = (await http.get(f"/api/bookings/{booking['id']}/history")).json()
        # No robot connected, but the server had just started: robots reconnect within
        # 30 s, so staff were not told "no robot online" (tests/server/test_booking_schedule.py
        # shows the flag of a scheduler running longer).
        assert [h["action"] for h in history] == ["created", "started"]


async def test_an_occurrence_claimed_just_before_a_crash_is_started_by_the_next_life(
    tmp_path: Path,
) -> None:
    """The start row is written, the process dies before the task exists: the next life
    creates it (once), and a third life does not create another."""
    settings = server_settings(tmp_path)
    async with running_server(settings) as srv:
        booking = await _book_soon(srv)
        assert await srv.app.state.booking_scheduler.store.claim(
            booking["id"], _at(booking), "started"
        )
    async with running_server(settings) as srv:
        await srv.app.state.booking_scheduler.step(_at(booking) + 3)
        [task] = _tasks_of(srv, booking)
        assert task.requester == requester_of(
            srv.app.state.bookings.get(booking["id"]), _at(booking)
        )
    async with running_server(settings) as srv:
        await srv.app.state.booking_scheduler.step(_at(booking) + 4)
        assert [t.id for t in _tasks_of(srv, booking)] == [task.id]


async def test_guidebot_bookings_on_the_command_line(server: RunningServer) -> None:
    """add, list, move, cancel, history through the CLI (in a thread: it is synchronous)."""
    runner = CliRunner()

    def run(*args: str) -> Result:
        return runner.invoke(
            bookings_cli, ["--server", server.url, "--token", OPERATOR_TOKEN, *args]
        )

    added = await asyncio.to_thread(
        run,
        "add",
        "--tour",
        "ground",
        "--at",
        tomorrow("11:00"),
        "--lang",
        "de",
        "--group",
        "12",
        "--every",
        "daily",
        "--except",
        tomorrow()[:10],
    )
    assert added.exit_code == 0, added.output
    booking = added.output.split()[1]
    listed = await asyncio.to_thread(run, "list", "--day", tomorrow()[:10])
    assert booking not in listed.output  # its first date is an exception
    moved = await asyncio.to_thread(run, "move", booking, "--group", "14")
    assert moved.exit_code == 0 and "14 people" in moved.output
    refused = await asyncio.to_thread(
        run, "add", "--tour", "nope", "--at", tomorrow(), "--lang", "en", "--group", "3"
    )
    assert refused.exit_code != 0 and "unknown tour 'nope'" in refused.output
    cancelled = await asyncio.to_thread(run, "cancel", booking, "--reason", "renovation")
    assert "CANCELLED" in cancelled.output
    history = await asyncio.to_thread(run, "history", booking)
    assert [line.split()[1] for line in history.output.splitlines()] == [
        "created",
        "moved",
        "cancelled",
    ]


async def test_the_panel_does_not_say_a_robot_is_free_when_the_free_one_is_kept_for_a_booking(
    tmp_path: Path,
) -> None:
    """R1 alone online and idle: "a robot is free now" until a booked tour in two minutes
    reserves it; then every tour would make it late, and the panel's line says busy with
    the wait (not "free now", which the idle robot alone made it say)."""
    async with running_server(server_settings(tmp_path)) as srv:
        r1 = RobotStub(srv.app.state.hub, "R1", "entrance")
        r1.state()
        manager = srv.app.state.task_manager
        async with client(srv, PANEL_TOKEN) as panel, client(srv, OPERATOR_TOKEN) as desk:
            await wait_until(lambda: manager.robots["R1"].online)
            assert (await panel.get("/api/visitor")).json()["service"] == "available"
            soon = dt.datetime.now(dt.UTC) + dt.timedelta(seconds=100)
            made = await desk.post(
                "/api/bookings", json=spanish(soon.strftime("%Y-%m-%dT%H:%M:%S"))
            )
            assert made.status_code == 201, made.text
            scheduler = srv.app.state.booking_scheduler
            await scheduler.step(time.time())
            assert scheduler.reservations.by_robot["R1"].booking == made.json()["id"]
            menu = (await panel.get("/api/visitor")).json()
        assert menu["service"] == "busy"
        assert all(t["estimate"]["service"] == "busy" for t in menu["tours"])
        assert menu["tours"][0]["estimate"]["eta_s"] > 60  # after the booked tour
