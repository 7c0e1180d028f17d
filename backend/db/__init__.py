"""Persistence: SQLAlchemy 2 async models, engine and Alembic migrations, the task store."""

from backend.db.session import log_failure, make_engine, make_sessionmaker, migrate
from backend.db.store import DbStore

__all__ = ["DbStore", "log_failure", "make_engine", "make_sessionmaker", "migrate"]
