"""The notification settings in the database (table ``notifications``, migration
0010): the SMTP server under the id ``smtp`` and one row per channel, each the
whole document (secrets included: they are needed to send). Written at once (an admin's change
is rare and its answer says it is kept), read back on start."""

from __future__ import annotations

from typing import Any

from pydantic import TypeAdapter
from sqlalchemy import JSON, Float, String, delete, select
from sqlalchemy.orm import Mapped, mapped_column

from backend.db.models import Base
from backend.notify.model import Channel, ChannelIn, Smtp

__all__ = ["NotificationRow", "NotifyStore"]

SMTP_ID = "smtp"
_CHANNEL = TypeAdapter(ChannelIn)


class NotificationRow(Base):
    """The SMTP server (``kind`` "smtp") or a channel with its rules (``kind`` "channel")."""

    __tablename__ = "notifications"
    id: Mapped[str] = mapped_column(String(40), primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    updated_at: Mapped[float] = mapped_column(Float)


class NotifyStore:
    def __init__(self, sessionmaker: Any) -> None:
        self.sessionmaker = sessionmaker

    async def load(self) -> tuple[Smtp | None, dict[str, Channel]]:
        async with self.sessionmaker() as session:
            rows = (await session.execute(select(NotificationRow))).scalars().all()
        smtp: Smtp | None = None
        channels: dict[str, Channel] = {}
        for row in rows:
            if row.kind == "smtp":
                smtp = Smtp.model_validate(row.data, strict=False)
            else:
                channels[row.id] = Channel(row.id, _CHANNEL.validate_python(row.data, strict=False))
        return smtp, channels

    async def save_smtp(self, smtp: Smtp, at: float) -> None:
        await self._merge(SMTP_ID, "smtp", smtp.model_dump(), at)

    async def save_channel(self, channel: Channel, at: float) -> None:
        await self._merge(channel.id, "channel", channel.rules.model_dump(), at)

    async def delete_channel(self, channel_id: str) -> None:
        async with self.sessionmaker() as session, session.begin():
            await session.execute(
                delete(NotificationRow).where(
                    NotificationRow.id == channel_id, NotificationRow.kind == "channel"
                )
            )

    async def _merge(self, row_id: str, kind: str, data: dict[str, Any], at: float) -> None:
        async with self.sessionmaker() as session, session.begin():
            await session.merge(NotificationRow(id=row_id, kind=kind, data=data, updated_at=at))
