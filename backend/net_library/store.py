"""Published nets in the database (table ``net_versions``, migration 0007_net_versions): every
version kept with who published it, when and why; a net's newest version is its live one."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from sqlalchemy import func, insert, select

from backend.db.models import NetVersionRow

__all__ = ["NetStore", "NetVersion"]


@dataclass(frozen=True)
class NetVersion:
    net: str
    version: int
    seq: int
    """The library's publication count when this version was published."""
    pnml: str
    published_by: str
    published_at: float
    note: str

    def summary(self) -> dict[str, Any]:
        """The version without its file (the history list)."""
        return {
            "version": self.version,
            "seq": self.seq,
            "published_by": self.published_by,
            "published_at": self.published_at,
            "note": self.note,
        }


def _version(row: NetVersionRow) -> NetVersion:
    return NetVersion(
        row.net, row.version, row.seq, row.pnml, row.published_by, row.published_at, row.note
    )


class NetStore:
    def __init__(self, sessionmaker: Any) -> None:
        self.sessionmaker = sessionmaker

    async def save(self, net: str, pnml: str, *, by: str, note: str) -> NetVersion:
        """Store ``pnml`` as the net's next version (its first is 1)."""
        now = time.time()
        async with self.sessionmaker() as session, session.begin():
            seq = (await session.scalar(select(func.max(NetVersionRow.seq)))) or 0
            last = await session.scalar(
                select(func.max(NetVersionRow.version)).where(NetVersionRow.net == net)
            )
            row = NetVersion(net, (last or 0) + 1, seq + 1, pnml, by, now, note)
            await session.execute(
                insert(NetVersionRow).values(
                    seq=row.seq,
                    net=net,
                    version=row.version,
                    pnml=pnml,
                    published_by=by,
                    published_at=now,
                    note=note,
                )
            )
            return row

    async def versions(self, net: str) -> list[NetVersion]:
        """Every kept version of ``net``, newest first."""
        async with self.sessionmaker() as session:
            rows = await session.scalars(
                select(NetVersionRow)
                .where(NetVersionRow.net == net)
                .order_by(NetVersionRow.version.desc())
            )
            return [_version(r) for r in rows]

    async def version(self, net: str, version: int) -> NetVersion | None:
        async with self.sessionmaker() as session:
            row = await session.scalar(
                select(NetVersionRow).where(
                    NetVersionRow.net == net, NetVersionRow.version == version
                )
            )
            return _version(row) if row is not None else None

    async def live(self) -> tuple[int, dict[str, NetVersion]]:
        """The library's publication count and each published net's newest version."""
        async with self.sessionmaker() as session:
            rows = await session.scalars(select(NetVersionRow).order_by(NetVersionRow.seq))
            newest = {r.net: _version(r) for r in rows}
        seq = max((v.seq for v in newest.values()), default=0)
        return seq, newest
