"""Leadership through PostgreSQL: exactly one server process runs the deciding services.

Each process holds one dedicated asyncpg connection and tries ``pg_try_advisory_lock`` every
``poll_s`` seconds. PostgreSQL holds the lock for as long as that session lives, so a leader that
dies (SIGKILL, machine lost) releases it when its connection drops and another process wins it
on its next try. The winner increments the leader epoch in the ``guidebot_leader`` row (the
fencing token, shown by /api/health) and then starts the deciding components.

Fencing: the leader checks its session every ``poll_s`` seconds. If the check fails (database
gone, connection cut, lock not held) it cannot know whether another process leads already, so it
stops deciding at once by calling ``on_lost`` (the server stops itself; a supervisor restarts it
as a follower). A leader paused longer than the database's connection timeout may still decide
until its first check after waking (docs/scaling.md, "Not covered").
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from typing import Any

import asyncpg

__all__ = ["LEADER_LOCK_KEY", "Leadership", "asyncpg_dsn"]

log = logging.getLogger(__name__)

LEADER_LOCK_KEY = 0x6775_6964_6562_6F74 & 0x7FFF_FFFF_FFFF_FFFF  # "guidebot"
_TABLE = """CREATE TABLE IF NOT EXISTS guidebot_leader (
    id integer PRIMARY KEY CHECK (id = 1),
    epoch bigint NOT NULL,
    process text NOT NULL,
    since timestamptz NOT NULL DEFAULT now())"""


def asyncpg_dsn(db_url: str) -> str:
    """The plain PostgreSQL DSN of a SQLAlchemy URL; ValueError for another database."""
    scheme, sep, rest = db_url.partition("://")
    if not sep or scheme.split("+")[0] not in ("postgresql", "postgres"):
        raise ValueError(f"leadership needs a PostgreSQL database, not {scheme!r}")
    return "postgresql://" + rest


class Leadership:
    """Campaign for the advisory lock; ``won`` is set while this process leads."""

    def __init__(
        self,
        db_url: str,
        process: str,
        *,
        on_lost: Callable[[], None],
        poll_s: float = 1.0,
        key: int = LEADER_LOCK_KEY,
    ) -> None:
        self.dsn = asyncpg_dsn(db_url)
        self.process = process
        self.on_lost = on_lost
        self.poll_s = poll_s
        self.key = key
        self.won = asyncio.Event()
        self.epoch: int | None = None
        """This process's leader epoch, once it leads."""
        self.leader: str | None = None
        """The process that leads, as last read from the database."""
        self.leader_epoch: int | None = None
        self.error = ""
        self.serving = False
        """The deciding components are up (set by backend/cluster.py): REST may be served."""
        self._task: asyncio.Task[None] | None = None

    @property
    def leading(self) -> bool:
        return self.won.is_set()

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run(), name="leadership")

    async def stop(self) -> None:
        """Stop campaigning; closing the connection releases the lock."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    def report(self) -> dict[str, Any]:
        return {
            "process": self.process,
            "leader": self.leader,
            "leading": self.leading,
            "serving": self.serving,
            "epoch": self.leader_epoch,
            "error": self.error,
        }

    async def _run(self) -> None:
        while not self.leading:
            try:
                conn = await asyncpg.connect(self.dsn, timeout=10)
            except (TimeoutError, OSError, asyncpg.PostgresError) as exc:
                self.error = f"cannot reach the database: {exc}"
                await asyncio.sleep(self.poll_s)
                continue
            try:
                await conn.execute(_TABLE)
                await self._campaign(conn)
                await self._hold(conn)
            except (OSError, asyncpg.PostgresError, asyncpg.InterfaceError) as exc:
                self.error = f"{type(exc).__name__}: {exc}"
                if self.leading:
                    log.critical("leadership: %s lost its lock (%s): stopping", self.process, exc)
                    self.won.clear()
                    self.serving = False
                    self.on_lost()
                    return
                await asyncio.sleep(self.poll_s)
            finally:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(conn.close(), 5)

    async def _campaign(self, conn: asyncpg.Connection) -> None:
        """Try the lock until won, reading who leads meanwhile."""
        while not await conn.fetchval("SELECT pg_try_advisory_lock($1)", self.key):
            row = await conn.fetchrow("SELECT epoch, process FROM guidebot_leader WHERE id = 1")
            if row is not None:
                self.leader_epoch, self.leader = row["epoch"], row["process"]
            self.error = ""
            await asyncio.sleep(self.poll_s)
        self.epoch = await conn.fetchval(
            """INSERT INTO guidebot_leader (id, epoch, process) VALUES (1, 1, $1)
               ON CONFLICT (id) DO UPDATE SET epoch = guidebot_leader.epoch + 1,
               process = EXCLUDED.process, since = now() RETURNING epoch""",
            self.process,
        )
        self.leader, self.leader_epoch, self.error = self.process, self.epoch, ""
        log.warning("leadership: %s leads (epoch %d)", self.process, self.epoch)
        self.won.set()

    async def _hold(self, conn: asyncpg.Connection) -> None:
        """Check every ``poll_s`` that the session still holds the lock; raise once it does not."""
        while True:
            await asyncio.sleep(self.poll_s)
            held = await asyncio.wait_for(
                conn.fetchval(
                    "SELECT count(*) FROM pg_locks WHERE locktype = 'advisory' AND granted"
                    " AND pid = pg_backend_pid() AND objid = ($1::bigint & 4294967295)::oid",
                    self.key,
                ),
                timeout=max(self.poll_s * 3, 3.0),
            )
            if not held:
                raise asyncpg.InterfaceError("the advisory lock is no longer held")
