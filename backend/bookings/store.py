"""Bookings in the database (tables of migration 0011): a booking is written at once
with its history entry (a staff action is rare and its answer says it is kept); an occurrence's
start row is written before its task exists, under the (booking, occurrence) primary key, so
two leaders, or one restarted, never start it twice."""

from __future__ import annotations

import time
from typing import Any

from sqlalchemy import JSON, Float, Integer, String, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Mapped, mapped_column

from backend.bookings.model import Booking, HistoryEntry
from backend.db.models import Base

__all__ = ["BookingRow", "BookingStartRow", "BookingStore", "HistoryRow"]


class BookingRow(Base):
    __tablename__ = "bookings"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    status: Mapped[str] = mapped_column(String(16), index=True)
    updated_at: Mapped[float] = mapped_column(Float)


class HistoryRow(Base):
    __tablename__ = "booking_history"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    booking: Mapped[str] = mapped_column(String(32), index=True)
    at: Mapped[float] = mapped_column(Float)
    by: Mapped[str] = mapped_column(String(64), default="")
    action: Mapped[str] = mapped_column(String(32))
    detail: Mapped[dict[str, Any]] = mapped_column(JSON)


class BookingStartRow(Base):
    """One occurrence the scheduler took: ``outcome`` started (a task), or missed (why)."""

    __tablename__ = "booking_starts"
    booking: Mapped[str] = mapped_column(String(32), primary_key=True)
    occurrence: Mapped[float] = mapped_column(Float, primary_key=True)
    started_at: Mapped[float] = mapped_column(Float)
    task_id: Mapped[str | None] = mapped_column(String(32), nullable=True)
    outcome: Mapped[str] = mapped_column(String(16))
    reason: Mapped[str] = mapped_column(String(500), default="")


class BookingStore:
    def __init__(self, sessionmaker: Any) -> None:
        self.sessionmaker = sessionmaker

    async def save(self, booking: Booking, entry: HistoryEntry) -> None:
        """The booking as it is now, and what changed it, in one transaction."""
        async with self.sessionmaker() as session, session.begin():
            await session.merge(
                BookingRow(
                    id=booking.id,
                    data=booking.model_dump(mode="json"),
                    status=booking.status,
                    updated_at=entry.at,
                )
            )
            session.add(_history_row(booking.id, entry))

    async def note(self, booking: str, entry: HistoryEntry) -> None:
        """A history entry alone (started, missed, flagged)."""
        async with self.sessionmaker() as session, session.begin():
            session.add(_history_row(booking, entry))

    async def load(self) -> list[Booking]:
        """Every booking kept (cancelled ones too: their history is asked for)."""
        async with self.sessionmaker() as session:
            rows = await session.execute(select(BookingRow.data))
            return [Booking.model_validate(data) for (data,) in rows]

    async def history(self, booking: str) -> list[HistoryEntry]:
        async with self.sessionmaker() as session:
            rows = await session.execute(
                select(HistoryRow).where(HistoryRow.booking == booking).order_by(HistoryRow.id)
            )
            return [
                HistoryEntry(at=r.at, by=r.by, action=r.action, detail=r.detail)
                for r in rows.scalars()
            ]

    async def claim(self, booking: str, occurrence: float, outcome: str, reason: str = "") -> bool:
        """Take an occurrence (before its task is created); False: it was taken already."""
        try:
            async with self.sessionmaker() as session, session.begin():
                session.add(
                    BookingStartRow(
                        booking=booking,
                        occurrence=occurrence,
                        started_at=time.time(),
                        task_id=None,
                        outcome=outcome,
                        reason=reason[:500],
                    )
                )
        except IntegrityError:
            return False
        return True

    async def started(
        self, booking: str, occurrence: float, task_id: str | None, **kw: str
    ) -> None:
        """The claimed occurrence's task (or, with outcome/reason, why it has none)."""
        async with self.sessionmaker() as session, session.begin():
            await session.execute(
                update(BookingStartRow)
                .where(
                    BookingStartRow.booking == booking,
                    BookingStartRow.occurrence == occurrence,
                )
                .values(task_id=task_id, **kw)
            )

    async def starts(self, since: float) -> list[dict[str, Any]]:
        """Occurrences taken at or after ``since`` (their outcome), oldest first."""
        async with self.sessionmaker() as session:
            rows = await session.execute(
                select(BookingStartRow)
                .where(BookingStartRow.occurrence >= since)
                .order_by(BookingStartRow.occurrence)
            )
            return [
                {
                    "booking": r.booking,
                    "occurrence": r.occurrence,
                    "started_at": r.started_at,
                    "task_id": r.task_id,
                    "outcome": r.outcome,
                    "reason": r.reason,
                }
                for r in rows.scalars()
            ]


def _history_row(booking: str, entry: HistoryEntry) -> HistoryRow:
    return HistoryRow(
        booking=booking, at=entry.at, by=entry.by[:64], action=entry.action, detail=entry.detail
    )
