"""Reports benchmark: a busy venue's year in the event log, folded into the hourly rollups,
then every report figure timed for a day, a week and a year.

    guidebot bench reports --events 5000000 --json

The log is generated, not run: ``--robots`` robots give tours from 9:00 to 19:00 every day
(created, assigned, started, per stop the nodes on the way, an area lock now and then, arrived
and explained, a third of the visitors leaving early; an elevator ride, a charge, now and then
a fault or a failed tour), written straight into a SQLite file with the rows the server writes,
as many days back from today as ``--events`` fills.

Last line: {"events", "days", "generate_s", "fold_s", "fold_events_per_s", "rollup_rows",
"db_mb", "events_mb", "report_ms": {"p50", "p99"}, "by_period": {day|week|year: {p50, p99}},
"by_figure": {figure: p99}, "summary_ms": {day|week|year}}. report_ms: one figure of one period
over REST's own code (Reports), five rounds; summary_ms: all figures at once (GET /api/reports).
"""

from __future__ import annotations

import asyncio
import datetime as dt
import random
import sqlite3
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import click
import orjson

from backend.db import make_engine, make_sessionmaker, migrate
from backend.reports.figures import FIGURES, Reports
from backend.reports.period import Period, parse_period
from backend.reports.rollup import Rollups
from guidebot.benchutil import percentiles, print_result

__all__ = ["main", "venue_events"]

ROUNDS = 5
NODES = {
    f"n{i}": ("ground" if i < 40 else "first", (i % 8) * 12.0, (i // 8) * 9.0) for i in range(60)
}
STOPS = [f"stop{i}" for i in range(14)]
TOURS = {"highlights": STOPS[:6], "romans": STOPS[4:10], "garden": STOPS[8:14]}
LANGS = ("en", "es", "fr", "de")
AREAS = ("corridor", "bridge", "lift_lobby", "shop", "cafe")
DOORS = ("d1", "d2", "d3", "d4")

Row = tuple[float, str, str, bytes]


def venue_events(day: dt.date, robots: int, rng: random.Random, *, prefix: str = "R") -> list[Row]:
    """One opening day's events, in time order, of robots ``{prefix}1`` to ``{prefix}{robots}``."""
    rows: list[Row] = []
    midnight = dt.datetime(day.year, day.month, day.day, tzinfo=dt.UTC).timestamp()
    seq = [0]

    def log(at: float, kind: str, source: str, data: dict[str, Any]) -> None:
        rows.append((at, kind, source, orjson.dumps(data)))

    log(midnight + 8.5 * 3600, "server_started", "server", {"site_version": 1})
    for r in range(robots):
        name = f"{prefix}{r + 1}"
        t = midnight + 8.75 * 3600 + rng.uniform(0, 600)
        log(t, "robot_connected", name, {"robot": name})
        node = rng.choice(list(NODES))
        charged = False
        while t < midnight + 19 * 3600:
            t += rng.expovariate(1 / 240)  # the next visitor comes
            seq[0] += 1
            task = f"{day:%j}{name}{seq[0]}"
            if not charged and t > midnight + 13 * 3600:
                charged = True
                t = _task(log, t, task, name, "charge", {}, rng, stops=[])
                continue
            tour = rng.choice(list(TOURS))
            params = {"tour": tour, "lang": rng.choice(LANGS)}
            t, node = _tour(log, t, task, name, params, TOURS[tour], node, rng)
        log(midnight + 19.25 * 3600, "robot_disconnected", name, {"robot": name})
    rows.sort(key=lambda row: row[0])
    return rows


def _task(
    log: Any,
    t: float,
    task: str,
    robot: str,
    kind: str,
    params: dict[str, Any],
    rng: random.Random,
    stops: list[str],
) -> float:
    base = {"task_id": task, "robot": None}
    log(t, "task_created", "task_manager", {**base, "state": "queued", "kind": kind, **params})
    t += rng.uniform(1, 20)
    log(t, "task_assigned", "task_manager", {**base, "state": "assigned", "robot": robot})
    t += rng.uniform(0.5, 3)
    log(t, "task_started", "task_manager", {**base, "state": "running", "robot": robot})
    t += rng.uniform(900, 1800)
    log(t, "task_done", "task_manager", {**base, "state": "done", "robot": robot})
    return t


def _tour(
    log: Any,
    t: float,
    task: str,
    robot: str,
    params: dict[str, Any],
    stops: list[str],
    node: str,
    rng: random.Random,
) -> tuple[float, str]:
    base = {"task_id": task}
    log(t, "task_created", "task_manager", {**base, "state": "queued", "kind": "tour", **params})
    t += rng.uniform(1, 30)
    log(t, "task_assigned", "task_manager", {**base, "state": "assigned", "robot": robot})
    t += rng.uniform(0.5, 3)
    log(t, "task_started", "task_manager", {**base, "state": "running", "robot": robot})
    running = {**base, "state": "running", "robot": robot}
    leave_after = rng.randint(1, len(stops)) if rng.random() < 0.33 else len(stops)
    for index, poi in enumerate(stops[:leave_after], start=1):
        for _ in range(rng.randint(2, 5)):
            t += rng.uniform(5, 20)
            node = rng.choice(list(NODES))
            log(t, "node_reached", robot, {"robot": robot, "node": node})
        if rng.random() < 0.3:
            area = rng.choice(AREAS)
            log(t, "area_requested", "traffic_manager", {"robot": robot, "area": area})
            t += rng.expovariate(1 / 8)
            log(t, "area_granted", "traffic_manager", {"robot": robot, "area": area})
        if rng.random() < 0.2:
            door = rng.choice(DOORS)
            log(t, "door_opened", "building", {"door": door})
            log(t + 6, "door_closed", "building", {"door": door})
        if rng.random() < 0.05:
            log(t, "call_elevator", robot, {"elevator": "lift", "floor": "first"})
            t += rng.uniform(15, 90)
            log(t, "elevator_in_position", "building", {"elevator": "lift", "floor": "first"})
        if rng.random() < 0.003:
            fault = {"robot": robot, "kind": "bumper", "detail": "pressed"}
            log(t, "robot_fault", robot, fault)
            failed = {**running, "state": "failed", "reason": "bumper pressed"}
            log(t + 1, "task_failed", "task_manager", failed)
            return t + 60, node
        progress = {"index": index, "total": len(stops), "poi": poi}
        log(
            t,
            f"task_point {index}/{len(stops)} arrived",
            "task_manager",
            {**running, **progress, "stage": "arrived"},
        )
        t += rng.uniform(60, 180)
        log(
            t,
            f"task_point {index}/{len(stops)} explained",
            "task_manager",
            {**running, **progress, "stage": "explained"},
        )
    log(t + 1, "task_done", "task_manager", {**base, "state": "done", "robot": robot})
    return t + 1, node


def fill(path: Path, events: int, robots: int, seed: int) -> int:
    """Write ``events`` (about) into the events table, the last day yesterday; the days."""
    rng = random.Random(seed)
    per_day = len(venue_events(dt.date(2026, 1, 5), robots, random.Random(seed)))
    days = max(1, round(events / per_day))
    today = dt.datetime.now(dt.UTC).date()
    connection = sqlite3.connect(path)
    try:
        connection.execute("PRAGMA journal_mode=WAL")
        connection.execute("PRAGMA synchronous=OFF")
        for back in range(days, 0, -1):
            rows = venue_events(today - dt.timedelta(days=back), robots, rng)
            connection.executemany(
                "INSERT INTO events (at, kind, source, data) VALUES (?, ?, ?, ?)", _text(rows)
            )
            connection.commit()
    finally:
        connection.close()
    return days


def _text(rows: list[Row]) -> Iterator[tuple[float, str, str, str]]:
    for at, kind, source, data in rows:
        yield at, kind, source, data.decode()


async def run(events: int, robots: int, seed: int, folder: Path) -> dict[str, Any]:
    path = folder / "reports.db"
    engine = make_engine(f"sqlite+aiosqlite:///{path}")
    try:
        await migrate(engine)
        started = time.perf_counter()
        days = await asyncio.to_thread(fill, path, events, robots, seed)
        generate_s = time.perf_counter() - started
        events_mb = path.stat().st_size / 1e6 + _wal(path)
        rollups = Rollups(make_sessionmaker(engine), NODES)
        started = time.perf_counter()
        folded = await rollups.catch_up()
        fold_s = time.perf_counter() - started
        reports = Reports(rollups)
        yesterday = (dt.datetime.now(dt.UTC).date() - dt.timedelta(days=1)).isoformat()
        week = (dt.datetime.now(dt.UTC).date() - dt.timedelta(days=7)).isoformat()
        year_start = (dt.datetime.now(dt.UTC).date() - dt.timedelta(days=365)).isoformat()
        periods: dict[str, Period] = {
            "day": parse_period(day=yesterday),
            "week": parse_period(week=week),
            "year": parse_period(start=year_start, end=yesterday),
        }
        samples: dict[str, list[float]] = {name: [] for name in periods}
        by_figure: dict[str, list[float]] = {name: [] for name in FIGURES}
        for _ in range(ROUNDS):
            for period_name, period in periods.items():
                for figure, method in FIGURES.items():
                    started = time.perf_counter()
                    await method(reports, period)
                    ms = (time.perf_counter() - started) * 1000
                    samples[period_name].append(ms)
                    by_figure[figure].append(ms)
        summary_ms = {}
        for period_name, period in periods.items():
            started = time.perf_counter()
            for method in FIGURES.values():
                await method(reports, period)
            summary_ms[period_name] = round((time.perf_counter() - started) * 1000, 1)
        async with engine.connect() as conn:
            rollup_rows = (
                await conn.exec_driver_sql("SELECT count(*) FROM report_rollups")
            ).scalar()
            total_events = (await conn.exec_driver_sql("SELECT count(*) FROM events")).scalar()
    finally:
        await engine.dispose()
    every = [ms for period_samples in samples.values() for ms in period_samples]
    return {
        "events": total_events,
        "folded": folded,
        "days": days,
        "robots": robots,
        "generate_s": round(generate_s, 1),
        "fold_s": round(fold_s, 1),
        "fold_events_per_s": round(folded / fold_s) if fold_s else None,
        "rollup_rows": rollup_rows,
        "events_mb": round(events_mb, 1),
        "db_mb": round(path.stat().st_size / 1e6 + _wal(path), 1),
        "report_ms": percentiles(every, 1),
        "by_period": {name: percentiles(s, 1) for name, s in samples.items()},
        "by_figure": {name: percentiles(s, 1)["p99"] for name, s in by_figure.items()},
        "summary_ms": summary_ms,
    }


def _wal(path: Path) -> float:
    wal = path.with_name(path.name + "-wal")
    return wal.stat().st_size / 1e6 if wal.exists() else 0.0


@click.command()
@click.option("--events", default=5_000_000, show_default=True, help="Events in the log (about).")
@click.option("--robots", default=12, show_default=True, help="Robots giving tours every day.")
@click.option("--seed", default=1, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line on stdout.")
def main(events: int, robots: int, seed: int, as_json: bool) -> None:
    """A year of a busy venue: fold the event log, time every report figure."""
    if events < 1000 or robots < 1:
        raise click.BadParameter("--events at least 1000, --robots at least 1")
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-reports-") as folder:
        result = asyncio.run(run(events, robots, seed, Path(folder)))
    if not as_json:
        click.echo(
            f"{result['events']} events over {result['days']} days folded in "
            f"{result['fold_s']} s into {result['rollup_rows']} rollup rows; "
            f"report p99 {result['report_ms']['p99']} ms",
            err=True,
        )
    print_result(result)
