"""The rollups: the event log folded hour by hour into ``report_rollups``, from where the
cursor (``report_cursor``) stopped, a chunk of events per transaction.

Additive: each chunk adds its counts to the hours' rows and moves the cursor in the same
transaction, only if the cursor is still where this fold read it; so two server processes
never count a chunk twice (the second's transaction changes nothing and is rolled back).
"""

from __future__ import annotations

import asyncio
import copy
import logging
import time
from typing import Any

from sqlalchemy import Insert, select, update
from sqlalchemy.dialects import postgresql, sqlite

from backend.db.models import EventRow, ReportCursorRow, ReportDayRow, ReportRollupRow
from backend.db.session import log_failure
from backend.reports.fold import Fold, Positions
from guidebot.site.schema import Site

__all__ = ["CHUNK", "Rollups", "Tally", "node_positions"]

log = logging.getLogger(__name__)

DAY = 86400
CHUNK = 5_000
"""Events folded per transaction (about 0.1 s of folding)."""

Tally = dict[tuple[str, int, str], list[float]]


def node_positions(site: Site) -> dict[str, tuple[str, float, float]]:
    """Node -> (floor, x, y): what the fold measures distances with."""
    return {node.id: (node.floor, node.x, node.y) for node in site.nodes}


class Rollups:
    """Keeps ``report_rollups`` up with the event log; ``tail`` gives what is not yet in them
    (the robots' time up to now)."""

    def __init__(self, sessionmaker: Any, positions: Positions | None = None) -> None:
        self.sessionmaker = sessionmaker
        self.positions: Positions = positions or {}
        self.folded = 0
        """Events folded by this process."""
        self._lock = asyncio.Lock()
        self._state: dict[str, Any] | None = None

    async def catch_up(self, *, chunk: int = CHUNK) -> int:
        """Fold every event written since the cursor; returns how many were folded."""
        async with self._lock:
            folded = 0
            while True:
                done = await self.fold_chunk(chunk)
                folded += done
                if done < chunk:
                    return folded

    async def fold_chunk(self, chunk: int = CHUNK) -> int:
        """Fold up to ``chunk`` events after the cursor in one transaction; returns how many
        (0 when another process moved the cursor meanwhile)."""
        async with self.sessionmaker() as session, session.begin():
            cursor = await session.get(ReportCursorRow, 1)
            last = cursor.last_event_id if cursor is not None else 0
            rows = (
                await session.execute(
                    select(EventRow.id, EventRow.at, EventRow.kind, EventRow.source, EventRow.data)
                    .where(EventRow.id > last)
                    .order_by(EventRow.id)
                    .limit(chunk)
                )
            ).all()
            state = copy.deepcopy(cursor.state) if cursor is not None else None
            self._state = state
            if not rows:
                return 0
            fold = Fold(state, self.positions)
            # Plain Python over thousands of rows: in a thread, so the hub's loop keeps
            # serving while a large log is caught up (the GIL is shared, not held throughout).
            await asyncio.to_thread(fold.feed, [(at, k, src, data) for _, at, k, src, data in rows])
            new_last = rows[-1][0]
            now = time.time()
            if cursor is None:
                session.add(
                    ReportCursorRow(id=1, last_event_id=new_last, state=fold.state, updated_at=now)
                )
            else:
                moved = await session.execute(
                    update(ReportCursorRow)
                    .where(ReportCursorRow.id == 1, ReportCursorRow.last_event_id == last)
                    .values(last_event_id=new_last, state=fold.state, updated_at=now)
                )
                if moved.rowcount != 1:  # type: ignore[attr-defined]
                    await session.rollback()
                    return 0  # another process folded it meanwhile
            await _add(session, fold.tally)
        # Committed (a busy database raises on the way out, before this): only now counted.
        self._state = fold.state
        self.folded += len(rows)
        return len(rows)

    async def tail(self, now: float) -> Tally:
        """What the rollups do not hold yet: each robot's time from its last event to ``now``
        (call ``catch_up`` first)."""
        if self._state is None:
            async with self.sessionmaker() as session:
                cursor = await session.get(ReportCursorRow, 1)
                self._state = cursor.state if cursor is not None else None
        fold = Fold(copy.deepcopy(self._state), self.positions)
        fold.close(now)
        return fold.tally

    async def run_periodically(self, every_s: float) -> None:
        """The server's background fold: every ``every_s``; a fold that fails wrote nothing
        (its chunk's transaction and cursor move together), and the next one folds it."""
        while True:
            await asyncio.sleep(every_s)
            try:
                await self.catch_up()
            except Exception as exc:  # a busy database: one warning line (log_failure)
                log_failure(log, exc, "report rollups failed; trying again in %.0f s", every_s)


async def _add(session: Any, tally: Tally) -> None:
    """Add the chunk's hours to ``report_rollups`` and their sums per UTC day to
    ``report_days``; each one statement compiled once, executed for every row."""
    days: Tally = {}
    hours = []
    for (metric, hour, key), (n, total) in tally.items():
        hours.append({"metric": metric, "hour": hour, "key": key, "n": int(n), "total": total})
        cell = days.setdefault((metric, hour // DAY * DAY, key), [0, 0.0])
        cell[0] += n
        cell[1] += total
    if hours:
        await session.execute(_upsert_adding(session, ReportRollupRow, "hour"), hours)
        rows = [
            {"metric": m, "day": d, "key": k, "n": int(c[0]), "total": float(c[1])}
            for (m, d, k), c in days.items()
        ]
        await session.execute(_upsert_adding(session, ReportDayRow, "day"), rows)


def _upsert_adding(session: Any, model: Any, when: str) -> Insert:
    """INSERT ... ON CONFLICT DO UPDATE n = n + new n, total = total + new total."""
    module = postgresql if session.bind.dialect.name == "postgresql" else sqlite
    statement = module.insert(model)
    table = model.__table__.c
    return statement.on_conflict_do_update(
        index_elements=[table.metric, table[when], table.key],
        set_={
            "n": table.n + statement.excluded.n,
            "total": table.total + statement.excluded.total,
        },
    )
