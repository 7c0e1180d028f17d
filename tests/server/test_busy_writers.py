"""Periodic writers on a busy SQLite database: one warning line, and the next run does the work.

A 30-minute soak logged "database is locked" tracebacks from periodic jobs while the event log's
writer held SQLite's write lock through a burst. Here a second real connection holds it (BEGIN
IMMEDIATE, as tests/server/test_db.py does) while the job runs its own loop: it says so in
warnings without a traceback (``backend.db.session.log_failure``), and once the lock is free its
next run writes what the failed one could not.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Coroutine, Iterator
from pathlib import Path
from typing import Any

import backend.bookings.schedule as schedule_module
import backend.reports.rollup as rollup_module
from backend.bookings.store import BookingStore
from backend.reports.rollup import Rollups
from backend.tasks import TaskManager
from guidebot.testing import wait_on, wait_until

from .test_booking_schedule import SCHOOL_GROUP, Clock, booked, local
from .test_db import sqlite_store, write_lock_held


class LogSeen(logging.Handler):
    """The records one logger writes while attached, with a wait for the next one."""

    def __init__(self, logger: logging.Logger) -> None:
        super().__init__(logging.DEBUG)
        self.logger = logger
        self.records: list[logging.LogRecord] = []
        self.changed = asyncio.Event()

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)
        self.changed.set()

    def problems(self) -> list[logging.LogRecord]:
        return [r for r in self.records if r.levelno >= logging.WARNING]

    async def first_problem(self) -> None:
        await wait_on(self.changed, self.problems, 30)

    @contextlib.contextmanager
    def attached(self) -> Iterator[LogSeen]:
        self.logger.addHandler(self)
        try:
            yield self
        finally:
            self.logger.removeHandler(self)


def assert_busy_warnings_only(seen: LogSeen) -> None:
    """Every problem logged is a one-line warning that the database was busy."""
    problems = seen.problems()
    assert problems, "nothing was logged"
    for record in problems:
        assert record.levelno == logging.WARNING and record.exc_info is None, record.getMessage()
        assert "the database is busy" in record.getMessage()


@contextlib.asynccontextmanager
async def running(job: Coroutine[Any, Any, None]) -> AsyncIterator[None]:
    """Run a periodic job's own loop for the block."""
    task = asyncio.get_running_loop().create_task(job)
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_report_rollups_wait_out_a_busy_database(tmp_path: Path) -> None:
    async with sqlite_store(tmp_path) as (store, path):
        for robot in ("R1", "R2", "R3"):
            store.record_event("robot_connected", "hub", {"robot": robot})
        await store.flush()
        rollups = Rollups(store.sessionmaker)
        with LogSeen(rollup_module.log).attached() as seen:
            async with running(rollups.run_periodically(0.01)):
                with write_lock_held(path):
                    await seen.first_problem()
                    assert rollups.folded == 0
                await wait_until(lambda: rollups.folded == 3, 30)
        assert_busy_warnings_only(seen)


async def test_the_booking_scheduler_waits_out_a_busy_database(
    tmp_path: Path, manager: TaskManager
) -> None:
    """The occurrence due while the lock is held is claimed (its row written) at the next
    pass, and its task made then: once, as ever."""
    async with sqlite_store(tmp_path) as (store, path):
        bookings = BookingStore(store.sessionmaker)
        clock = Clock(local("09:00"))
        service, _, scheduler = booked(manager, bookings, clock)
        booking = await service.create(SCHOOL_GROUP, by="desk")
        clock.now = local("10:30") + 1
        scheduler.tick_s = 0.01
        requester = f"booking:{booking.id}@{int(local('10:30'))}"

        def tasks() -> list[str]:
            return [t.id for t in manager.tasks.values() if t.requester == requester]

        with LogSeen(schedule_module.log).attached() as seen, contextlib.ExitStack() as held:
            held.enter_context(write_lock_held(path))  # before the scheduler's first pass
            async with scheduler:
                await seen.first_problem()
                assert tasks() == []
                held.close()  # the lock is free again
                await wait_until(lambda: bool(tasks()), 30)
                # The task is made, then its row written: wait for that write (CI stopped the
                # scheduler in between; a restart finds the task and writes it then).
                row = await written(bookings, local("10:00"))
        assert len(tasks()) == 1
        assert (row["outcome"], row["task_id"]) == ("started", tasks()[0])
        assert_busy_warnings_only(seen)


async def written(bookings: BookingStore, since: float) -> dict[str, Any]:
    """The one occurrence row from ``since`` once its task id is written (up to 30 s)."""
    async with asyncio.timeout(30):
        while True:
            rows = await bookings.starts(since)
            if rows and rows[0]["task_id"]:
                [row] = rows
                return row
            await asyncio.sleep(0.01)
