"""Accounts and sessions in the database (tables ``accounts``, ``account_sessions``).

Sessions are read from the database on every request that carries a session cookie (one
primary-key lookup), so an account disabled or signed out anywhere is refused at once by
every server process; nothing of a session but the digest of its cookie is stored."""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from typing import Any

from sqlalchemy import delete, select, update
from sqlalchemy.exc import IntegrityError

from backend.db.models import AccountRow, AccountSessionRow

__all__ = ["Account", "AccountExists", "AccountStore", "StoredSession"]


@dataclass(frozen=True, slots=True)
class Account:
    name: str
    display_name: str
    role: str
    password_hash: str
    disabled: bool
    created_at: float
    changed_at: float
    last_sign_in: float | None

    def public(self) -> dict[str, Any]:
        """What the accounts API shows: everything but the password's hash."""
        return {
            "name": self.name,
            "display_name": self.display_name,
            "role": self.role,
            "disabled": self.disabled,
            "has_password": bool(self.password_hash),
            "created_at": self.created_at,
            "changed_at": self.changed_at,
            "last_sign_in": self.last_sign_in,
        }


@dataclass(frozen=True, slots=True)
class StoredSession:
    digest: str
    account: str
    created_at: float
    seen_at: float
    address: str


class AccountExists(ValueError):
    """An account of that name exists already."""


_ACCOUNT_FIELDS = tuple(f.name for f in fields(Account))


def _account(row: AccountRow) -> Account:
    return Account(**{name: getattr(row, name) for name in _ACCOUNT_FIELDS})


class AccountStore:
    """Reads and writes accounts and sessions, each call its own short transaction."""

    def __init__(self, sessionmaker: Any) -> None:
        self.sessionmaker = sessionmaker

    async def get(self, name: str) -> Account | None:
        async with self.sessionmaker() as db:
            row = await db.get(AccountRow, name)
            return _account(row) if row is not None else None

    async def all(self) -> list[Account]:
        async with self.sessionmaker() as db:
            rows = (await db.execute(select(AccountRow).order_by(AccountRow.name))).scalars()
            return [_account(row) for row in rows]

    async def count(self) -> int:
        return len(await self.all())

    async def create(self, name: str, display_name: str, role: str, password_hash: str) -> Account:
        now = time.time()
        row = AccountRow(
            name=name,
            display_name=display_name,
            role=role,
            password_hash=password_hash,
            disabled=False,
            created_at=now,
            changed_at=now,
            last_sign_in=None,
        )
        try:
            async with self.sessionmaker() as db, db.begin():
                db.add(row)
        except IntegrityError:
            raise AccountExists(f"an account named {name!r} exists already") from None
        return _account(row)

    async def change(self, name: str, **values: Any) -> Account | None:
        """Set the given columns (and ``changed_at``); None when there is no such account."""
        async with self.sessionmaker() as db, db.begin():
            row = await db.get(AccountRow, name)
            if row is None:
                return None
            for key, value in values.items():
                setattr(row, key, value)
            if "last_sign_in" not in values:
                row.changed_at = time.time()
            return _account(row)

    # --- sessions --------------------------------------------------------------------------
    async def add_session(self, session: StoredSession) -> None:
        async with self.sessionmaker() as db, db.begin():
            db.add(AccountSessionRow(**{f.name: getattr(session, f.name) for f in fields(session)}))

    async def session(self, digest: str) -> tuple[StoredSession, Account] | None:
        """The session of that cookie digest and its account, or None."""
        async with self.sessionmaker() as db:
            found = (
                await db.execute(
                    select(AccountSessionRow, AccountRow)
                    .join(AccountRow, AccountRow.name == AccountSessionRow.account)
                    .where(AccountSessionRow.digest == digest)
                )
            ).first()
        if found is None:
            return None
        row, account = found
        stored = StoredSession(
            **{f.name: getattr(row, f.name) for f in fields(StoredSession)}  # type: ignore[arg-type]
        )
        return stored, _account(account)

    async def touch(self, digest: str, seen_at: float) -> None:
        await self.change_session(digest, seen_at=seen_at)

    async def change_session(self, digest: str, **values: float) -> None:
        """Set a session's times (``seen_at``; tests age ``created_at`` too)."""
        async with self.sessionmaker() as db, db.begin():
            await db.execute(
                update(AccountSessionRow).where(AccountSessionRow.digest == digest).values(**values)
            )

    async def end_session(self, digest: str) -> None:
        async with self.sessionmaker() as db, db.begin():
            await db.execute(delete(AccountSessionRow).where(AccountSessionRow.digest == digest))

    async def end_sessions(self, account: str) -> int:
        """End every session of ``account``; how many there were."""
        async with self.sessionmaker() as db, db.begin():
            result = await db.execute(
                delete(AccountSessionRow).where(AccountSessionRow.account == account)
            )
            return int(result.rowcount or 0)  # type: ignore[attr-defined]

    async def end_expired(self, idle_before: float, created_before: float) -> int:
        async with self.sessionmaker() as db, db.begin():
            result = await db.execute(
                delete(AccountSessionRow).where(
                    (AccountSessionRow.seen_at < idle_before)
                    | (AccountSessionRow.created_at < created_before)
                )
            )
            return int(result.rowcount or 0)  # type: ignore[attr-defined]

    async def live_digests(self, digests: set[str]) -> set[str]:
        """Which of ``digests`` are still sessions."""
        if not digests:
            return set()
        async with self.sessionmaker() as db:
            rows = await db.execute(
                select(AccountSessionRow.digest).where(AccountSessionRow.digest.in_(digests))
            )
            return {digest for (digest,) in rows}
