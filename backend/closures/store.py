"""Staff closures in the database (table ``closures``, migration 0006_closures): written at
once (a staff action is rare and its answer says it is kept), read back on start."""

from __future__ import annotations

import time
from typing import Any

from sqlalchemy import delete, or_, select

from backend.closure import Closure
from backend.db.models import ClosureRow

__all__ = ["ClosureStore"]


class ClosureStore:
    def __init__(self, sessionmaker: Any) -> None:
        self.sessionmaker = sessionmaker

    async def save(self, closure: Closure) -> None:
        async with self.sessionmaker() as session, session.begin():
            await session.merge(
                ClosureRow(id=closure.id, data=closure.model_dump(), end=closure.end)
            )

    async def delete(self, closure_id: str) -> None:
        async with self.sessionmaker() as session, session.begin():
            await session.execute(delete(ClosureRow).where(ClosureRow.id == closure_id))

    async def load(self, now: float | None = None) -> list[Closure]:
        """Every closure not over at ``now`` (those over are deleted)."""
        now = time.time() if now is None else now
        async with self.sessionmaker() as session, session.begin():
            await session.execute(
                delete(ClosureRow).where(ClosureRow.end.is_not(None), ClosureRow.end <= now)
            )
            rows = await session.execute(
                select(ClosureRow.data).where(or_(ClosureRow.end.is_(None), ClosureRow.end > now))
            )
            return [Closure.model_validate(data) for (data,) in rows]
