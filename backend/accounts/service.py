"""Signing people in and out: password checks with per-address and per-account limits,
sessions (a random cookie whose SHA-256 digest is stored, a CSRF token, idle and absolute
expiry), the hub links opened under a session, closed when it ends (sign-out, "sign out
everywhere", an account disabled or its role changed, expiry).

Every sign-in, failed sign-in and account change is recorded in the event log with the
account and the client's address (``audit``); never a password, cookie or token."""

from __future__ import annotations

import contextlib
import hashlib
import logging
import re
import secrets
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from fastapi import status

from backend.accounts import passwords
from backend.accounts.store import Account, AccountStore, StoredSession
from backend.auth import PERSON_ROLES, Principal, Role, SignInRefused, token_digest
from backend.hub.core import CLOSE_UNAUTHORIZED, RemoteClient
from backend.ratelimit import RateLimited, RateLimiter

__all__ = [
    "ACCOUNT_NAME",
    "AccountError",
    "AccountService",
    "Audit",
    "Session",
    "account_name_problem",
    "csrf_token",
]

log = logging.getLogger(__name__)

ACCOUNT_NAME = re.compile(r"^[a-z][a-z0-9._-]{1,31}$")
TOUCH_EVERY_S = 30.0
"""A session's last use is written at most this often (each request reads it)."""


def csrf_token(cookie: str) -> str:
    """A session's CSRF token, derived from its cookie: never stored, and neither the
    cookie nor the stored digest can be found from it (nor it from the digest)."""
    return hashlib.sha256(f"guidebot-csrf:{cookie}".encode()).hexdigest()


def account_name_problem(name: str) -> str | None:
    if not ACCOUNT_NAME.match(name):
        return (
            "an account name is 2 to 32 characters: lowercase letters, digits, '.', '-' or '_', "
            "starting with a letter"
        )
    return None


class AccountError(Exception):
    """A refused account change: ``status_code`` 404 (no such account), 409 (exists, or the
    last admin), 422 (a bad name, role or password)."""

    def __init__(self, status_code: int, reason: str) -> None:
        super().__init__(reason)
        self.status_code = status_code
        self.reason = reason


@dataclass(frozen=True, slots=True)
class Session:
    """A live session as a request sees it."""

    digest: str
    principal: Principal
    display_name: str
    csrf: str
    expires_at: float


Audit = Callable[[str, str, dict[str, Any]], None]
"""(kind, source, data) -> recorded in the event log."""


class AccountService:
    def __init__(
        self,
        store: AccountStore,
        *,
        failures: RateLimiter,
        lockouts: RateLimiter,
        audit: Audit,
        idle_s: float,
        max_s: float,
        min_length: int = passwords.DEFAULT_MIN_LENGTH,
        reserved: Callable[[], set[str]] = set,
    ) -> None:
        """``failures``: failed sign-ins per address, shared with the token sign-in;
        ``lockouts``: failed sign-ins per account; ``reserved``: names an account may not
        take (tokens' and robots' names: the hub knows clients by name)."""
        self.store = store
        self.failures = failures
        self.lockouts = lockouts
        self.audit = audit
        self.idle_s = idle_s
        self.max_s = max_s
        self.min_length = min_length
        self.reserved = reserved
        self._links: dict[str, set[RemoteClient]] = {}
        self._owners: dict[str, str] = {}
        """Session digest -> account, for the sessions with hub links."""

    # --- signing in and out ----------------------------------------------------------------
    def _refuse_if_locked(self, address: str, name: str) -> None:
        wait = max(self.failures.wait_time(address), self.lockouts.wait_time(name))
        if wait > 0:
            retry = max(1, int(wait + 0.999))
            raise SignInRefused(
                status.HTTP_429_TOO_MANY_REQUESTS,
                f"too many failed sign-in attempts; try again in {retry} s",
                retry,
            )

    def _failed(self, name: str, address: str, why: str) -> SignInRefused:
        spent = [(self.failures, address)] + ([(self.lockouts, name)] if name else [])
        for limiter, key in spent:
            with contextlib.suppress(RateLimited):
                limiter.spend(key, "failed sign-ins")
        source = name or "unknown"
        self.audit("sign_in_failed", source, {"account": name, "address": address, "why": why})
        return SignInRefused(status.HTTP_401_UNAUTHORIZED, "wrong account name or password")

    async def sign_in(self, name: str, password: str, address: str) -> tuple[str, Session]:
        """A new session (its cookie value, then the session) or SignInRefused: 401 for a
        wrong name or password (the same answer for both), 429 after too many failures
        from this address or for this account, 403 for a disabled account."""
        name = name.strip().lower()[:64]
        self._refuse_if_locked(address, name)
        account = await self.store.get(name) if ACCOUNT_NAME.match(name) else None
        stored = account.password_hash if account is not None else ""
        if not await passwords.verify_password(stored, password) or account is None:
            raise self._failed(name, address, "unknown account" if account is None else "password")
        if account.disabled:
            self.audit(
                "sign_in_failed", name, {"account": name, "address": address, "why": "disabled"}
            )
            raise SignInRefused(status.HTTP_403_FORBIDDEN, "this account is disabled")
        self.lockouts.forget(name)
        if passwords.needs_rehash(account.password_hash):
            await self.store.change(name, password_hash=await passwords.hash_password(password))
        return await self.open_session(account, address, "password")

    async def open_session(self, account: Account, address: str, how: str) -> tuple[str, Session]:
        """A new session for ``account`` (signed in by ``how``: password, passkey): its
        cookie value, then the session."""
        cookie = secrets.token_urlsafe(32)
        now = time.time()
        row = StoredSession(
            digest=token_digest(cookie),
            account=account.name,
            created_at=now,
            seen_at=now,
            address=address[:64],
        )
        await self.store.add_session(row)
        await self.store.change(account.name, last_sign_in=now)
        signed_in = {"account": account.name, "address": address, "with": how}
        self.audit("signed_in", account.name, signed_in)
        return cookie, self._session(row, account, cookie)

    def refuse_if_locked(self, address: str, name: str = "") -> None:
        """SignInRefused 429 while this address (or account) is over its failure budget."""
        self._refuse_if_locked(address, name)

    def failed(self, name: str, address: str, why: str, reason: str = "") -> SignInRefused:
        """Count a failed sign-in (address and account) and record it; the 401 to raise
        (``reason``: its text, else the password sign-in's)."""
        refused = self._failed(name, address, why)
        if reason:
            refused.reason = reason
        return refused

    def _session(self, row: StoredSession, account: Account, cookie: str) -> Session:
        return Session(
            digest=row.digest,
            principal=Principal(name=account.name, role=Role(account.role)),
            display_name=account.display_name,
            csrf=csrf_token(cookie),
            expires_at=min(row.seen_at + self.idle_s, row.created_at + self.max_s),
        )

    async def session(self, cookie: str | None) -> Session | None:
        """The live session of a cookie value, or None (unknown, ended, expired, disabled);
        an expired one is ended here."""
        if not cookie or len(cookie) > 128:
            return None
        found = await self.store.session(token_digest(cookie))
        if found is None:
            return None
        row, account = found
        now = time.time()
        expired = now - row.seen_at > self.idle_s or now - row.created_at > self.max_s
        if expired or account.disabled:
            await self.end(row.digest)
            return None
        if now - row.seen_at > min(TOUCH_EVERY_S, self.idle_s / 10):
            await self.store.touch(row.digest, now)
            row = StoredSession(row.digest, row.account, row.created_at, now, row.address)
        return self._session(row, account, cookie)

    async def end(self, digest: str) -> None:
        """End one session and close its hub links."""
        await self.store.end_session(digest)
        self._close_links({digest}, "signed out")

    async def sign_out(self, session: Session, address: str) -> None:
        await self.end(session.digest)
        name = session.principal.name
        self.audit("signed_out", name, {"account": name, "address": address})

    async def end_all(self, account: str, reason: str) -> int:
        """End every session of ``account`` (on every page: each request reads the database;
        this process's hub links now, other processes' at their next sweep)."""
        count = await self.store.end_sessions(account)
        self._close_links({d for d, a in self._owners.items() if a == account}, reason)
        return count

    # --- hub links -------------------------------------------------------------------------
    def link(self, session: Session, client: RemoteClient) -> None:
        """A hub connection opened under this session: closed when the session ends."""
        self._links.setdefault(session.digest, set()).add(client)
        self._owners[session.digest] = session.principal.name

    def unlink(self, digest: str, client: RemoteClient) -> None:
        links = self._links.get(digest)
        if links is not None:
            links.discard(client)
            if not links:
                del self._links[digest]
                del self._owners[digest]

    def _close_links(self, digests: set[str], reason: str) -> None:
        for digest in digests:
            for client in list(self._links.get(digest, ())):
                client.request_close(CLOSE_UNAUTHORIZED, f"session ended: {reason}")

    async def sweep(self, *, expire: bool = True) -> None:
        """End expired sessions (``expire``: the leader's job); close the hub links of
        sessions that ended elsewhere."""
        now = time.time()
        if expire:
            await self.store.end_expired(now - self.idle_s, now - self.max_s)
        linked = set(self._links)
        if not linked:
            return
        gone = linked - await self.store.live_digests(linked)
        self._close_links(gone, "expired or signed out")

    # --- accounts --------------------------------------------------------------------------
    async def _checked_password(self, name: str, password: str) -> str:
        problem = passwords.password_problem(password, name, self.min_length)
        if problem is not None:
            raise AccountError(422, problem)
        return await passwords.hash_password(password)

    @staticmethod
    def _checked_role(role: str) -> str:
        if role not in {r.value for r in PERSON_ROLES}:
            allowed = ", ".join(sorted(r.value for r in PERSON_ROLES))
            raise AccountError(422, f"unknown role {role!r}: one of {allowed}")
        return role

    async def create(
        self, name: str, role: str, password: str, display_name: str = "", *, by: str, address: str
    ) -> Account:
        problem = account_name_problem(name)
        if problem is not None:
            raise AccountError(422, problem)
        if name in self.reserved():
            raise AccountError(409, f"{name!r} is the name of a token or robot: choose another")
        self._checked_role(role)
        if await self.store.get(name) is not None:
            raise AccountError(409, f"an account named {name!r} exists already")
        hashed = await self._checked_password(name, password)
        account = await self.store.create(name, display_name.strip()[:128], role, hashed)
        self._changed(by, address, name, "created", role=role)
        return account

    async def change(
        self,
        name: str,
        *,
        by: str,
        address: str,
        role: str | None = None,
        display_name: str | None = None,
        disabled: bool | None = None,
    ) -> Account:
        """Change an account; a new role or disabling it ends its sessions at once."""
        account = await self._existing(name)
        values: dict[str, Any] = {}
        if role is not None and role != account.role:
            values["role"] = self._checked_role(role)
        if display_name is not None:
            values["display_name"] = display_name.strip()[:128]
        if disabled is not None and disabled != account.disabled:
            values["disabled"] = disabled
        if account.role == Role.ADMIN and (values.get("role") or values.get("disabled")):
            await self._keep_an_admin(name)
        changed = await self.store.change(name, **values)
        assert changed is not None
        if "role" in values or values.get("disabled"):
            await self.end_all(name, "disabled" if values.get("disabled") else "role changed")
        if values:
            details = {k: v for k, v in values.items() if k != "display_name"}
            self._changed(by, address, name, "changed", **details)
        return changed

    async def reset_password(self, name: str, password: str, *, by: str, address: str) -> Account:
        """A new password set by an admin (or the person): ends the account's sessions."""
        await self._existing(name)
        hashed = await self._checked_password(name, password)
        changed = await self.store.change(name, password_hash=hashed)
        assert changed is not None
        await self.end_all(name, "password changed")
        self._changed(by, address, name, "password_set")
        return changed

    async def _existing(self, name: str) -> Account:
        account = await self.store.get(name)
        if account is None:
            raise AccountError(404, f"no account named {name!r}")
        return account

    async def _keep_an_admin(self, name: str) -> None:
        admins = [a for a in await self.store.all() if a.role == Role.ADMIN and not a.disabled]
        if [a.name for a in admins] == [name]:
            raise AccountError(409, "this is the last enabled admin account: keep one")

    def _changed(self, by: str, address: str, account: str, change: str, **data: Any) -> None:
        self.audit(
            "account_changed",
            by,
            {"account": by, "address": address, "target": account, "change": change, **data},
        )
