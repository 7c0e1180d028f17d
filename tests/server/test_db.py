"""Migrations ship in the package and build the schema on an empty database."""

from __future__ import annotations

import contextlib
import logging
import sqlite3
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import asyncpg
import pytest
from sqlalchemy import inspect, text
from sqlalchemy.exc import DBAPIError

from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.tasks.model import Task, TaskState

from .postgres import PostgresServer


@contextlib.asynccontextmanager
async def sqlite_store(tmp_path: Path) -> AsyncIterator[tuple[DbStore, Path]]:
    """A started store on a migrated SQLite file (and the file, for a second connection)."""
    path = tmp_path / "guidebot.db"
    engine = make_engine(f"sqlite+aiosqlite:///{path}")
    try:
        await migrate(engine)
        store = DbStore(make_sessionmaker(engine))
        await store.start()
        yield store, path
        await store.stop()
    finally:
        await engine.dispose()


@contextlib.contextmanager
def write_lock_held(path: Path) -> Iterator[None]:
    """Another writer holding SQLite's write lock (BEGIN IMMEDIATE) while the block runs."""
    other = sqlite3.connect(path, isolation_level=None)
    other.execute("BEGIN IMMEDIATE")
    try:
        yield
    finally:
        other.execute("ROLLBACK")
        other.close()


async def test_migrations_build_the_schema_and_the_store_round_trips(db_url: str) -> None:
    engine = make_engine(db_url)
    try:
        await migrate(engine)
        await migrate(engine)  # idempotent: already at head
        async with engine.connect() as conn:
            tables = await conn.run_sync(lambda c: set(inspect(c).get_table_names()))
        assert {"site", "tasks", "task_history", "events", "alembic_version"} <= tables
        store = DbStore(make_sessionmaker(engine))
        await store.start()
        task = Task("t1", "go_to", {"node": "hall"}, 3, "admin", 1)
        store.record(task, "created")
        task.move(TaskState.ASSIGNED)
        task.robot = "R1"
        store.record(task, "assigned")
        await store.stop()
        [loaded] = await store.load_open_tasks()
        assert (loaded.id, loaded.state, loaded.robot) == ("t1", TaskState.ASSIGNED, "R1")
        assert [h["state"] for h in await store.history("t1")] == ["queued", "assigned"]
        assert await store.max_seq() == 1
        assert await store.save_site({"name": "x"}) == 1
        assert await store.save_site({"name": "y"}) == 2
        assert await store.load_site() == (2, {"name": "y"})
    finally:
        await engine.dispose()


async def test_the_locks_of_the_last_server_life_are_replayed_from_the_event_log(
    db_url: str,
) -> None:
    """What was held when the server died comes back at the next start (docs/server.md)."""
    engine = make_engine(db_url)
    try:
        await migrate(engine)
        store = DbStore(make_sessionmaker(engine))
        await store.start()
        assert await store.lock_holders() == {}
        log = store.record_event
        log("server_started", "server", {})
        log("area_granted", "traffic_manager", {"robot": "R9", "area": "corridor"})
        log("server_started", "server", {})  # an earlier life's grants are not this one's
        log("area_granted", "traffic_manager", {"robot": "R1", "area": "corridor"})
        log("area_granted", "traffic_manager", {"robot": "R2", "area": "elevator"})
        log("area_granted", "traffic_manager", {"robot": "R3", "area": "stairs"})
        log("area_released", "traffic_manager", {"robot": "R1", "area": "corridor"})
        log("area_granted", "traffic_manager", {"robot": "R4", "area": "corridor"})
        log("area_released", "traffic_manager", {"robot": "R9", "area": "elevator"})  # not its
        log("area_force_released", "traffic_manager", {"area": "stairs", "robot": "R3", "by": "x"})
        log("area_granted", "traffic_manager", {"robot": 7, "area": "bad row"})
        assert await store.lock_holders() == {"corridor": "R4", "elevator": "R2"}
        await store.stop()
    finally:
        await engine.dispose()


async def test_a_read_while_another_writer_holds_the_database_answers_what_is_written(
    tmp_path: Path,
) -> None:
    """GET /api/tasks flushes pending rows first; when another writer holds SQLite's write lock
    past the busy time-out (the reports' rollup on a loaded machine did), the read answers what
    is written instead of failing with 500, and nothing pending is lost."""
    async with sqlite_store(tmp_path) as (store, path):
        first = Task("t1", "go_to", {"node": "hall"}, 3, "admin", 1)
        store.record(first, "created")
        await store.flush()
        with write_lock_held(path):  # as a long transaction holds it
            second = Task("t2", "go_to", {"node": "hall"}, 3, "admin", 2)
            store.record(second, "created")
            total, tasks = await store.list_tasks()
            assert (total, [t.id for t in tasks]) == (1, ["t1"])
        await store.flush()
        total, tasks = await store.list_tasks()
        assert sorted(t.id for t in tasks) == ["t1", "t2"]


async def test_the_writer_meeting_another_writer_s_lock_past_the_time_out_logs_no_traceback(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The write-behind writer meeting SQLite's write lock held past the busy time-out (a
    burst on a loaded machine: the soak's session sweep met it) says so in one warning line,
    keeps the rows queued and writes them once the lock is free."""
    from tests.server.test_api import eventually

    async with sqlite_store(tmp_path) as (store, path):
        with write_lock_held(path), caplog.at_level(logging.WARNING, logger="backend.db.store"):
            store.record(Task("t1", "go_to", {"node": "hall"}, 3, "admin", 1), "created")
            said = await eventually(
                lambda: [r for r in caplog.records if r.name == "backend.db.store"], timeout=60
            )
        assert said[0].levelno == logging.WARNING and said[0].exc_info is None
        assert "database is busy" in said[0].getMessage()
        await eventually(lambda: store.written == 3)  # the task, its history row, its event
        assert [t.id for t in (await store.list_tasks())[1]] == ["t1"]


async def test_a_server_frozen_inside_a_transaction_does_not_hold_its_row_locks_for_ever(
    postgres: PostgresServer,
) -> None:
    """A server process stopped mid-transaction (SIGSTOP, a paused VM) held its row locks, and
    the one taking over the lead waited on them for ever (the failover bench's pause mode).
    PostgreSQL ends a session of ours idle in its transaction (session.py): the lock comes free
    and the frozen session's next statement fails (it was ended). The second connection is a
    plain one, with no limit of its own: without the fix it waits until the test's time-out."""
    url = postgres.database()
    engine = make_engine(url)
    other = await asyncpg.connect(url.replace("postgresql+asyncpg://", "postgresql://"))
    try:
        await migrate(engine)
        store = DbStore(make_sessionmaker(engine))
        assert await store.save_site({"name": "x"}) == 1
        async with engine.connect() as frozen:
            await frozen.execute(text("SELECT version FROM site FOR UPDATE"))  # then stops
            async with other.transaction():
                assert await other.fetchval("SELECT version FROM site FOR UPDATE") == 1
            with pytest.raises(DBAPIError):  # the frozen session was ended
                await frozen.execute(text("SELECT 1"))
    finally:
        await other.close()
        await engine.dispose()
