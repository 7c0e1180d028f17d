"""The reports' figures, folded from an event log written through the store's own API (the
calls the Task Manager, the Traffic Manager, the hub logger and the alert store make), on both
databases (docs/reports.md)."""

from __future__ import annotations

import dataclasses
import datetime as dt
from collections.abc import AsyncIterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from click.testing import CliRunner

import backend.db.store as store_module
import backend.tasks.model as model_module
from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.reports.cli import replay_command
from backend.reports.figures import Reports, percentile
from backend.reports.fold import ROBOT_STATES, bucket
from backend.reports.period import BadPeriod, parse_period
from backend.reports.replay import replay
from backend.reports.rollup import Rollups
from backend.tasks.model import Task, TaskState

DAY = dt.datetime(2026, 7, 14, tzinfo=dt.UTC)
POSITIONS = {
    "hall": ("ground", 0.0, 0.0),
    "p1": ("ground", 30.0, 0.0),
    "p2": ("ground", 30.0, 40.0),
    "p3": ("first", 0.0, 0.0),
}


def at(hour: int, minute: int = 0, second: int = 0) -> float:
    return DAY.replace(hour=hour, minute=minute, second=second).timestamp()


class VenueDay:
    """Writes a museum's morning into the event log through DbStore, at chosen times."""

    def __init__(self, store: DbStore, monkeypatch: pytest.MonkeyPatch) -> None:
        self.store = store
        self.now = at(9)
        clock = SimpleNamespace(time=lambda: self.now)
        monkeypatch.setattr(store_module, "time", clock)
        monkeypatch.setattr(model_module, "time", clock)
        self.seq = 0

    def when(self, hour: int, minute: int = 0, second: int = 0) -> VenueDay:
        self.now = at(hour, minute, second)
        return self

    def log(self, kind: str, data: dict[str, Any], source: str = "hub") -> None:
        self.store.record_event(kind, source, data)

    def task(self, kind: str, **params: Any) -> Task:
        self.seq += 1
        task = Task(f"t{self.seq}", kind, params, 3, "kiosk-1", self.seq)
        self.store.record(task, "created")
        return task

    def start(self, task: Task, robot: str) -> None:
        task.robot = robot
        task.move(TaskState.ASSIGNED)
        self.store.record(task, "assigned")
        task.move(TaskState.RUNNING)
        self.store.record(task, "started")

    def point(self, task: Task, index: int, total: int, poi: str, stage: str) -> None:
        detail = {"index": index, "total": total, "poi": poi, "stage": stage}
        self.store.record(task, f"point {index}/{total} {stage}", detail)

    def end(self, task: Task, state: TaskState, reason: str = "") -> None:
        task.move(state, reason=reason)
        self.store.record(task, state.value)


@pytest.fixture
async def store(db_url: str) -> AsyncIterator[DbStore]:
    engine = make_engine(db_url)
    await migrate(engine)
    store = DbStore(make_sessionmaker(engine))
    await store.start()
    yield store
    await store.stop()
    await engine.dispose()


def write_morning(day: VenueDay) -> None:
    """Two robots, four tours (one left after two of three stops, one failed, one cancelled),
    a charge, a lock wait, an elevator wait, a fault and a blocked door."""
    day.when(9).log("server_started", {"site_version": 1}, "server")
    day.log("robot_connected", {"robot": "R1"})
    day.log("robot_connected", {"robot": "R2"})
    # Tour 1 (Spanish): asked 10:00, the robot at the first stop 10:03; left after stop 2.
    tour = day.when(10).task("tour", tour="highlights", lang="es")
    day.when(10, 1).start(tour, "R1")
    day.log("node_reached", {"robot": "R1", "node": "hall"})
    day.when(10, 3).point(tour, 1, 3, "p1", "arrived")
    day.log("node_reached", {"robot": "R1", "node": "p1"})  # 30 m
    day.when(10, 5).point(tour, 1, 3, "p1", "explained")
    day.when(10, 6).log("area_requested", {"robot": "R1", "area": "corridor", "chain": []}, "tm")
    day.when(10, 6, 30).log("area_granted", {"robot": "R1", "area": "corridor"}, "tm")
    day.when(10, 8).point(tour, 2, 3, "p2", "arrived")
    day.log("node_reached", {"robot": "R1", "node": "p2"})  # 40 m
    day.when(10, 10).point(tour, 2, 3, "p2", "explained")
    day.when(10, 11).end(tour, TaskState.DONE)
    # Tour 2 (English): asked 10:30, at the first stop 10:31, all three stops, done 11:10.
    tour = day.when(10, 30).task("tour", tour="highlights", lang="en")
    day.when(10, 30, 20).start(tour, "R2")
    day.when(10, 31).point(tour, 1, 3, "p1", "arrived")
    for index, poi, minute in ((1, "p1", 35), (2, "p2", 45), (3, "p3", 58)):
        day.when(10, minute).point(tour, index, 3, poi, "explained")
    day.when(10, 50).log("call_elevator", {"elevator": "lift", "floor": "first"}, "R2")
    day.when(10, 51).log("elevator_in_position", {"elevator": "lift", "floor": "first"})
    day.when(11, 10).end(tour, TaskState.DONE)
    # Tour 3 fails at 11:20 (navigation); tour 4 is cancelled before it starts.
    tour = day.when(11, 15).task("tour", tour="garden")
    day.start(tour, "R1")
    day.when(11, 16).log(
        "alert_raised",
        {"kind": "robot_fault", "subject": "R1/navigation", "count": 1, "id": "a1"},
        "console",
    )
    day.log("robot_fault", {"robot": "R1", "kind": "navigation", "detail": "blocked"}, "R1")
    day.when(11, 20).end(tour, TaskState.FAILED, "navigation to p1 failed: blocked")
    day.when(11, 26).log(
        "alert_resolved",
        {"kind": "robot_fault", "subject": "R1/navigation", "count": 1, "id": "a1"},
        "console",
    )
    day.log(
        "alert_raised",
        {"kind": "building_command_failed", "subject": "open_door:d1", "count": 1, "id": "a2"},
        "console",
    )
    tour = day.when(11, 30).task("tour", tour="garden")
    day.when(11, 35).end(tour, TaskState.CANCELLED, "cancelled by the visitor")
    # R2 charges from 11:40 to 12:00.
    charge = day.when(11, 40).task("charge")
    day.start(charge, "R2")
    day.when(12).end(charge, TaskState.DONE)
    day.when(12, 30).log("robot_disconnected", {"robot": "R1"})
    day.log("robot_disconnected", {"robot": "R2"})


async def test_a_mornings_figures_from_the_event_log(
    store: DbStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_morning(VenueDay(store, monkeypatch))
    reports = Reports(Rollups(store.sessionmaker, POSITIONS), store.flush)
    await check_morning(reports)
    # Whole UTC days come from the daily rollups, the hours around them from the hourly ones.
    day = (await reports.following(parse_period(day="2026-07-14")))["rows"]
    across = parse_period(start="2026-07-13T12:00", end="2026-07-15T06:00")
    assert (await reports.following(across))["rows"] == day
    ten = parse_period(start="2026-07-14T10:00", end="2026-07-14T11:00")
    assert [k["requested"] for k in (await reports.tasks(ten))["by_kind"]] == [2]


async def check_morning(reports: Reports) -> None:
    """The figures of ``write_morning``'s day."""
    day = parse_period(day="2026-07-14")

    tasks = await reports.tasks(day)
    assert tasks["by_kind"] == [
        {"kind": "charge", "requested": 1, "done": 1, "failed": 0, "cancelled": 0},
        {"kind": "tour", "requested": 4, "done": 2, "failed": 1, "cancelled": 1},
    ]
    assert tasks["failed_by_reason"] == [{"reason": "navigation to p1 failed: blocked", "count": 1}]
    hours = {row["start"]: row for row in tasks["rows"]}
    assert len(hours) == 24
    assert hours["2026-07-14 10:00"] == {
        "start": "2026-07-14 10:00",
        "requested": 2,
        "done": 1,
        "failed": 0,
        "cancelled": 0,
    }
    assert hours["2026-07-14 11:00"]["done"] == 1
    assert hours["2026-07-14 11:00"]["failed"] == 1

    waits = await reports.waits(day)
    # Waits 180 s and 60 s; tours done in 660 s and 2400 s (buckets: up to 5 % low).
    assert waits["wait_s"]["count"] == 2
    assert waits["wait_s"]["mean"] == 120.0
    assert 60 * 0.95 <= waits["wait_s"]["p50"] <= 60
    assert 180 * 0.95 <= waits["wait_s"]["p95"] <= 180
    assert waits["tour_length_s"]["count"] == 2
    assert 2400 * 0.95 <= waits["tour_length_s"]["p95"] <= 2400

    following = await reports.following(day)
    assert (following["tours"], following["stopped"], following["share"]) == (2, 1, 0.5)
    rows = {(r["by"], r["name"]): (r["tours"], r["stopped"]) for r in following["rows"]}
    assert rows == {
        ("tour", "highlights"): (2, 1),
        ("lang", "es"): (1, 1),
        ("lang", "en"): (1, 0),
        ("stop", "p2"): (2, 1),
    }

    stops = await reports.stops(day)
    assert stops["rows"] == [
        {"stop": "p1", "listened": 2},
        {"stop": "p2", "listened": 2},
        {"stop": "p3", "listened": 1},
    ]

    robots = {r["robot"]: r for r in (await reports.robots(day))["rows"]}
    # R1: idle 9:00-10:01, touring to 10:11, idle to 11:15, touring to 11:16, faulted to
    # 11:26, idle to 12:30, then offline (the rest of the day is not counted: it is past).
    assert robots["R1"]["touring_s"] == 10 * 60 + 60
    assert robots["R1"]["faulted_s"] == 10 * 60
    assert robots["R1"]["idle_s"] == 61 * 60 + 64 * 60 + 64 * 60
    assert robots["R1"]["distance_m"] == 70.0
    assert robots["R2"]["charging_s"] == 20 * 60
    assert robots["R2"]["touring_s"] == 40 * 60 - 20

    incidents = {(r["type"], r["name"]): r for r in (await reports.incidents(day))["rows"]}
    assert incidents["lock_wait", "corridor"]["wait_mean_s"] == 30.0
    assert incidents["elevator_wait", "lift"]["wait_total_s"] == 60.0
    assert incidents["faults", "R1|navigation"]["count"] == 1
    assert incidents["door_blocks", "d1"]["count"] == 1
    assert incidents["alarms", "robot_fault"]["count"] == 1

    heat = {(r["kind"], r["name"]): r["count"] for r in (await reports.heat(day))["rows"]}
    assert heat[("area", "corridor")] == 1
    assert heat[("node", "p1")] == 1

    # The day before holds nothing; a week holds the same day's figures, binned by day.
    assert (await reports.tasks(parse_period(day="2026-07-13")))["by_kind"] == []
    week = await reports.tasks(parse_period(week="2026-07-13"))
    assert [r["requested"] for r in week["rows"]] == [0, 4, 0, 0, 0, 0, 0]
    assert week["rows"][1]["start"] == "2026-07-14"


async def test_the_fold_goes_on_where_it_stopped_and_counts_nothing_twice(
    store: DbStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Folded a few events at a time, or by two folders over the same database, the figures
    are those of one fold over the whole log."""
    write_morning(VenueDay(store, monkeypatch))
    await store.flush()
    first, second = Rollups(store.sessionmaker, POSITIONS), Rollups(store.sessionmaker, POSITIONS)
    while await first.fold_chunk(3) + await second.fold_chunk(5):
        pass
    assert first.folded and second.folded
    assert first.folded + second.folded == len(await store.events(limit=1000))
    await check_morning(Reports(first))
    await check_morning(Reports(second))


def test_percentiles_from_buckets_are_at_most_five_percent_low() -> None:
    values = [float(v) for v in range(1, 1001)]
    histogram: dict[str, int] = {}
    for value in values:
        histogram[bucket(value)] = histogram.get(bucket(value), 0) + 1
    p50, p95 = percentile(histogram, 0.5), percentile(histogram, 0.95)
    assert p50 is not None and 500 * 0.95 <= p50 <= 500
    assert p95 is not None and 950 * 0.95 <= p95 <= 950
    assert percentile({}, 0.5) is None


@pytest.mark.parametrize(
    ("params", "says"),
    [
        ({}, "give one period"),
        ({"day": "2026-07-14", "week": "2026-07-13"}, "give one period"),
        ({"day": "14/07/2026"}, "is not a date"),
        ({"start": "2026-07-14T10:00"}, "needs both start and end"),
        ({"start": "2026-07-14T10:00", "end": "2026-07-14T09:00"}, "ends before it starts"),
        ({"start": "2025-01-01", "end": "2026-07-14"}, "longer than 400 days"),
        ({"day": "2026-07-14", "tz": "Mars/Olympus"}, "unknown time zone"),
        ({"start": "yesterday", "end": "2026-07-14"}, "is not a date and time"),
    ],
)
def test_a_bad_period_says_what_is_wrong(params: dict[str, str], says: str) -> None:
    with pytest.raises(BadPeriod, match=says):
        parse_period(**params)


def test_a_day_is_the_venues_day() -> None:
    period = parse_period(day="2026-07-14", tz="Europe/Madrid")
    assert period.start == dt.datetime(2026, 7, 13, 22, tzinfo=dt.UTC).timestamp()
    assert period.end - period.start == 86400
    assert period.label(period.start) == "2026-07-14 00:00"
    custom = parse_period(start="2026-07-14T10:20", end="2026-07-14T12:05")
    assert (custom.start, custom.end) == (at(10), at(13))


async def test_retention_keeps_what_the_rollups_have_not_folded(
    store: DbStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Pruned before the fold read them, a day's events would be missing from every report."""
    write_morning(VenueDay(store, monkeypatch))
    await store.flush()
    rollups = Rollups(store.sessionmaker, POSITIONS)
    assert await rollups.fold_chunk(10) == 10
    total = len(await store.events(limit=1000))
    pruned = await store.prune_events(older_than=at(23))
    assert pruned == 10 - 1  # the folded ones, but this life's server_started
    assert len(await store.events(limit=1000)) == total - pruned
    await check_morning(Reports(rollups))


def test_day_bins_read_the_daily_rollups_only_on_utc_days() -> None:
    assert parse_period(week="2026-07-13").utc_days()
    assert not parse_period(week="2026-07-13", tz="Europe/Madrid").utc_days()
    assert not parse_period(day="2026-07-14").utc_days()  # hour by hour
    winter_to_summer = parse_period(start="2026-01-01", end="2026-07-01", tz="Europe/London")
    assert not winter_to_summer.utc_days()


async def test_a_replay_has_the_periods_events_and_the_state_it_starts_from(
    store: DbStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_morning(VenueDay(store, monkeypatch))
    await store.flush()
    half = parse_period(start="2026-07-14T10:30", end="2026-07-14T11:00")
    # Periods are whole hours; the player asks for any, this one from 10:30.
    played = await replay(store.sessionmaker, dataclasses.replace(half, start=at(10, 30)))
    # At 10:30 R1 stood at p2 (reached 10:08) and held the corridor (granted 10:06:30).
    assert played["start"]["robots"] == {"R1": "p2"}
    assert played["start"]["locks"] == {"corridor": "R1"}
    # The tour's request and progress too: ``guidebot plan --replay`` plays its requests.
    assert [(e["at"], e["kind"]) for e in played["events"]] == [
        (at(10, 30), "task_created"),
        (at(10, 30, 20), "task_started"),
        (at(10, 31), "task_point 1/3 arrived"),
        (at(10, 35), "task_point 1/3 explained"),
        (at(10, 45), "task_point 2/3 explained"),
        (at(10, 51), "elevator_in_position"),
        (at(10, 58), "task_point 3/3 explained"),
    ]
    assert played["truncated"] is False
    with pytest.raises(BadPeriod, match="at most 24 hours"):
        await replay(store.sessionmaker, parse_period(week="2026-07-13"))


def test_bins_are_the_venues_hours_or_days_across_a_clock_change() -> None:
    spring = parse_period(start="2026-03-28", end="2026-04-01", tz="Europe/Madrid")
    labels = [spring.label(b) for b in spring.bins()]
    assert labels == ["2026-03-28", "2026-03-29", "2026-03-30", "2026-03-31"]
    assert spring.bins()[2] - spring.bins()[1] == 23 * 3600  # the clocks went forward
    day = parse_period(day="2026-03-29", tz="Europe/Madrid")
    assert len(day.bins()) == 23 and day.label(day.bins()[3]) == "2026-03-29 04:00"


def test_guidebot_replay_refuses_more_than_a_day(tmp_path: Path) -> None:
    args = ["--from", f"sqlite+aiosqlite:///{tmp_path}/x.db", "--start", "2026-07-13"]
    args += ["--end", "2026-07-15", "--out", str(tmp_path / "r.json")]
    result = CliRunner().invoke(replay_command, args)
    assert result.exit_code == 2 and "at most 24 hours" in result.output
    assert not (tmp_path / "r.json").exists()


async def test_the_time_the_server_was_down_counts_as_down(
    store: DbStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A clean stop logs ``server_stopped``: down until the next start. A crash logs nothing:
    down from the last event it logged. Robots are offline from a start until they connect."""
    day = VenueDay(store, monkeypatch)
    day.when(9).log("server_started", {"site_version": 1}, "server")
    day.log("robot_connected", {"robot": "R1"})
    day.when(10).log("server_stopped", {}, "server")
    day.when(11).log("server_started", {"site_version": 1}, "server")
    day.when(11, 5).log("robot_connected", {"robot": "R1"})
    day.when(12).log("node_reached", {"robot": "R1", "node": "p1"})  # then it crashed
    day.when(14).log("server_started", {"site_version": 1}, "server")
    day.when(14, 1).log("robot_connected", {"robot": "R1"})
    day.when(15).log("robot_disconnected", {"robot": "R1"})
    reports = Reports(Rollups(store.sessionmaker, POSITIONS), store.flush)
    period = parse_period(start="2026-07-14T09:00", end="2026-07-14T15:00")
    (r1,) = (await reports.robots(period))["rows"]
    assert r1["down_s"] == 3600 + 2 * 3600
    assert r1["offline_s"] == 5 * 60 + 60
    assert r1["idle_s"] == (60 + 55 + 59) * 60
    assert sum(r1[f"{s}_s"] for s in ROBOT_STATES) == 6 * 3600
