"""Engine, sessions and migrations. SQLite file by default, PostgreSQL by URL.

Migrations (Alembic, shipped in backend/db/migrations) run at start-up over the app's own
async engine, so a fresh file and an old one both end at the current schema.
"""

from __future__ import annotations

import logging
import sqlite3
from pathlib import Path

import orjson
from alembic import command
from alembic.config import Config
from sqlalchemy import event
from sqlalchemy.engine import Connection
from sqlalchemy.exc import OperationalError
from sqlalchemy.ext.asyncio import AsyncEngine, async_sessionmaker, create_async_engine

__all__ = [
    "JsonText",
    "UnstorableJson",
    "alembic_config",
    "database_busy",
    "log_failure",
    "make_engine",
    "make_sessionmaker",
    "migrate",
    "unstorable",
]

MIGRATIONS = Path(__file__).resolve().parent / "migrations"


class UnstorableJson(ValueError):
    """A document the database's JSON columns cannot hold (an integer beyond 64 bits): the
    caller's mistake, answered 422, never a server error (found by the API fuzz)."""


def unstorable(exc: Exception) -> UnstorableJson:
    """The caller's error for what the JSON writer refused."""
    return UnstorableJson(f"the document cannot be stored: {exc} (integers must fit in 64 bits)")


class JsonText(str):
    """A JSON column's value already written (a large document, written off the event loop):
    stored as it is."""


def _json_text(value: object) -> str:
    if isinstance(value, JsonText):
        return str(value)
    try:
        return orjson.dumps(value).decode()
    except orjson.JSONEncodeError as exc:
        raise unstorable(exc) from None


def make_engine(url: str) -> AsyncEngine:
    """An async engine; SQLite gets WAL and a busy time-out so readers never block writers.

    JSON columns are written with orjson: SQLAlchemy serialises on the event loop, and the
    standard library takes about 50 ms for a 10 000-node site document, orjson about 5."""
    connect_args: dict[str, object] = {}
    if url.startswith("postgresql+asyncpg"):
        # A server process frozen inside a transaction (SIGSTOP, a VM paused) keeps its row
        # locks; the process that takes over the lead would wait on them for ever (the
        # failover bench's pause mode: the new leader's start blocked on the old one's report
        # rollup row). PostgreSQL ends such a session after 5 s idle in its transaction.
        connect_args["server_settings"] = {"idle_in_transaction_session_timeout": "5000"}
    engine = create_async_engine(
        url,
        pool_pre_ping=True,
        json_serializer=_json_text,
        json_deserializer=orjson.loads,
        connect_args=connect_args,
    )
    if engine.dialect.name == "sqlite":

        @event.listens_for(engine.sync_engine, "connect")
        def _pragmas(dbapi_connection, _record):  # type: ignore[no-untyped-def]
            cursor = dbapi_connection.cursor()
            cursor.execute("PRAGMA journal_mode=WAL")
            cursor.execute("PRAGMA busy_timeout=5000")
            cursor.execute("PRAGMA synchronous=NORMAL")
            cursor.close()

    return engine


def database_busy(exc: BaseException) -> bool:
    """Whether ``exc`` is SQLite's "database is locked": another connection held the write lock
    past the busy time-out (``make_engine``). Under a burst of writes (the event log's writer
    taking the lock back again and again) a waiting writer can lose for that long; nothing of
    its transaction was written, so a periodic job logs it in one line and tries again at its
    next run instead of logging a traceback."""
    orig = exc.orig if isinstance(exc, OperationalError) else exc
    code = getattr(orig, "sqlite_errorcode", None) if isinstance(orig, sqlite3.Error) else None
    return code is not None and code & 0xFF in (sqlite3.SQLITE_BUSY, sqlite3.SQLITE_LOCKED)


def log_failure(logger: logging.Logger, exc: BaseException, message: str, *args: object) -> None:
    """A periodic job's failure, the job trying again later: a busy database
    (``database_busy``) in one warning line, anything else with its traceback."""
    if database_busy(exc):
        orig = getattr(exc, "orig", exc)
        logger.warning(message + " (the database is busy: %s)", *args, orig)
    else:
        logger.error(message, *args, exc_info=exc)


def make_sessionmaker(engine: AsyncEngine) -> async_sessionmaker:  # type: ignore[type-arg]
    return async_sessionmaker(engine, expire_on_commit=False)


def alembic_config(url: str | None = None) -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    if url:
        cfg.set_main_option("sqlalchemy.url", url)
    return cfg


async def migrate(engine: AsyncEngine, revision: str = "head") -> None:
    """Upgrade the database to ``revision`` on a connection of ``engine``."""

    def upgrade(connection: Connection) -> None:
        cfg = alembic_config()
        cfg.attributes["connection"] = connection
        command.upgrade(cfg, revision)

    async with engine.begin() as conn:
        await conn.run_sync(upgrade)
