"""Leadership through PostgreSQL: exactly one server process runs the deciding services.

Each process holds one dedicated asyncpg connection and tries ``pg_try_advisory_lock`` every
``poll_s`` seconds. PostgreSQL holds the lock for as long as that session lives, so a leader that
dies (SIGKILL, machine lost) releases it when its connection drops and another process wins it
on its next try. The winner increments the leader epoch in the ``guidebot_leader`` row (the
fencing token, shown by /api/health) and then starts the deciding components.

Lease and fencing: every session sets PostgreSQL's ``idle_session_timeout`` to ``lease_s``, so
the server ends a leader session that has been silent that long (a paused, frozen or cut-off
leader) and the lock goes to a follower. The leader renews by checking its lock every ``poll_s``;
each confirmed check extends its local lease to the moment the check was sent plus ``lease_s``
(minus a tenth for clock drift): PostgreSQL's idle clock starts later than that, so no other
process can lead before the local lease ends. ``may_decide()`` is true only within it, and the
deciding components' endpoints ask it before every message they handle or send
(backend/fencing.py). If a check fails the leader calls ``on_lost`` (the server stops itself; a
supervisor restarts it as a follower).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable
from typing import Any

import asyncpg

from guidebot.service import Service

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


class Leadership(Service):
    """Campaign for the advisory lock; ``won`` is set while this process leads."""

    def __init__(
        self,
        db_url: str,
        process: str,
        *,
        on_lost: Callable[[], None],
        poll_s: float = 1.0,
        lease_s: float = 4.0,
        key: int = LEADER_LOCK_KEY,
    ) -> None:
        super().__init__()
        if lease_s < 2 * poll_s:
            raise ValueError(f"the lease ({lease_s} s) must be at least twice the poll ({poll_s})")
        self.dsn = asyncpg_dsn(db_url)
        self.process = process
        self.on_lost = on_lost
        self.poll_s = poll_s
        self.lease_s = lease_s
        self.key = key
        self._lease_until = 0.0
        """time.monotonic() until which no other process can lead (this one's lease)."""
        self.won = asyncio.Event()
        self.epoch: int | None = None
        """This process's leader epoch, once it leads."""
        self.leader: str | None = None
        """The process that leads, as last read from the database."""
        self.leader_epoch: int | None = None
        self.error = ""
        self.serving = False
        """The deciding components are up (set by backend/cluster.py): REST may be served."""

    @property
    def leading(self) -> bool:
        return self.won.is_set()

    def may_decide(self) -> bool:
        """This process leads and its lease runs: the fence every decision passes."""
        return self.won.is_set() and time.monotonic() < self._lease_until

    def _renewed(self, sent_at: float) -> None:
        self._lease_until = sent_at + self.lease_s * 0.9

    async def on_start(self) -> None:
        """Campaign until stopped; stopping closes the connection, which releases the lock."""
        self.spawn(self._run(), name="leadership")

    def fencing_epoch(self) -> int | None:
        """The epoch this process won, while it believes it leads: its database writes check
        it against the leader row (the row, not the lease, says who leads now)."""
        return self.epoch if self.leading else None

    def report(self) -> dict[str, Any]:
        return {
            "process": self.process,
            "leader": self.leader,
            "leading": self.leading,
            "serving": self.serving,
            "epoch": self.leader_epoch,
            "lease_s": self.lease_s,
            "may_decide": self.may_decide(),
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
                # The lease: PostgreSQL ends this session once it is silent for lease_s.
                await conn.execute(f"SET idle_session_timeout = {int(self.lease_s * 1000)}")
                await conn.execute(_TABLE)
                await self._campaign(conn)
                await self._hold(conn)
            except Exception as exc:  # any failure of the lock's session: the lock may be gone
                # (asyncpg raises OSError, PostgresError, InterfaceError, InternalClientError)
                self.error = f"{type(exc).__name__}: {exc}"
                if self.leading:
                    log.critical("leadership: %s lost its lock (%s): stopping", self.process, exc)
                    self.won.clear()
                    self.serving = False
                    self._lease_until = 0.0
                    self.on_lost()
                    return
                await asyncio.sleep(self.poll_s)
            finally:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(conn.close(), 5)

    async def _campaign(self, conn: asyncpg.Connection) -> None:
        """Try the lock until won, reading who leads meanwhile."""
        while True:
            sent_at = time.monotonic()
            if await conn.fetchval("SELECT pg_try_advisory_lock($1)", self.key):
                break
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
        self._renewed(sent_at)
        self.leader, self.leader_epoch, self.error = self.process, self.epoch, ""
        log.warning("leadership: %s leads (epoch %d)", self.process, self.epoch)
        self.won.set()

    async def _hold(self, conn: asyncpg.Connection) -> None:
        """Check every ``poll_s`` that the session still holds the lock; raise once it does not."""
        while True:
            await asyncio.sleep(self.poll_s)
            sent_at = time.monotonic()
            held = await asyncio.wait_for(
                conn.fetchval(
                    "SELECT count(*) FROM pg_locks WHERE locktype = 'advisory' AND granted"
                    " AND pid = pg_backend_pid() AND objid = ($1::bigint & 4294967295)::oid",
                    self.key,
                ),
                timeout=self.lease_s,
            )
            if not held:
                raise asyncpg.InterfaceError("the advisory lock is no longer held")
            self._renewed(sent_at)
