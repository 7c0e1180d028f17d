"""The accounts component (backend.app.COMPONENTS, after the server brain: it needs the
database): ``app.state.accounts`` (the service) and ``app.state.sessions`` (the cookie gate
the token checks consult), and a sweeper ending expired sessions and the hub links of
sessions ended by another server process.

With several server processes (docs/scaling.md) the component runs on the leader only; a
follower reads people's sessions from the shared database through ``follower_sessions``, so a
page signed in by its cookie opens its hub link on any process."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from typing import Any

from fastapi import FastAPI

from backend.accounts.cookies import CookieGate
from backend.accounts.oidc import OidcConfig, SingleSignOn
from backend.accounts.passkeys import PasskeyService
from backend.accounts.service import AccountService, Audit
from backend.accounts.store import AccountStore
from backend.db import log_failure, make_engine, make_sessionmaker
from backend.ratelimit import RateLimiter
from backend.state import app_state

__all__ = ["SWEEP_EVERY_S", "accounts", "follower_sessions", "sweep_once"]

log = logging.getLogger(__name__)

SWEEP_EVERY_S = 5.0


def reserved_names(app: FastAPI) -> set[str]:
    """Names an account may not take: the tokens' and the site's robots' (hub names)."""
    settings = app.state.settings
    names = {"admin", "hub", "console"} | {t.name for t in settings.tokens}
    sites = app_state(app).sites
    if sites is not None:
        names |= {robot.name for robot in sites.site.robots}
    return names


def _service(app: FastAPI, sessionmaker: Any, audit: Audit) -> AccountService:
    settings = app.state.settings
    return AccountService(
        AccountStore(sessionmaker),
        failures=app.state.auth.failures,
        lockouts=RateLimiter(
            per_minute=settings.sign_in_failures_per_minute, burst=settings.sign_in_failure_burst
        ),
        audit=audit,
        idle_s=settings.session_idle_minutes * 60,
        max_s=settings.session_max_hours * 3600,
        min_length=settings.password_min_length,
        reserved=lambda: reserved_names(app),
    )


async def sweep_once(service: AccountService, *, expire: bool) -> bool:
    """One sweep; False when it failed, logged, and the next one tries again. SQLite busy past
    its time-out (another writer holding the lock through a burst: a 30-minute soak met it) is
    one warning line, not a traceback: the sweep's transaction wrote nothing, and an expired
    session is refused by every request meanwhile (``AccountService.session``). The wait is in
    the database driver's thread: the event loop keeps serving."""
    try:
        await service.sweep(expire=expire)
    except Exception as exc:
        log_failure(
            log, exc, "accounts: the session sweep failed; trying again in %.0f s", SWEEP_EVERY_S
        )
        return False
    return True


@contextlib.asynccontextmanager
async def _sweeping(service: AccountService, *, expire: bool) -> AsyncIterator[None]:
    """Every ``SWEEP_EVERY_S``: end expired sessions (``expire``) and close the hub links of
    sessions ended elsewhere."""

    async def sweep() -> None:
        while True:
            await asyncio.sleep(SWEEP_EVERY_S)
            await sweep_once(service, expire=expire)

    sweeper = asyncio.create_task(sweep(), name="accounts-sweeper")
    try:
        yield
    finally:
        sweeper.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await sweeper


@contextlib.asynccontextmanager
async def accounts(app: FastAPI) -> AsyncIterator[None]:
    store = app.state.store

    def audit(kind: str, source: str, data: dict[str, Any]) -> None:
        store.record_event(kind, source[:64], data)

    service = _service(app, store.sessionmaker, audit)
    app.state.accounts = service
    app.state.passkeys = PasskeyService(service)
    sso = OidcConfig.from_settings(app.state.settings)
    app.state.sso = SingleSignOn(sso, service) if sso is not None else None
    app.state.sessions = CookieGate(service)
    try:
        async with _sweeping(service, expire=True):
            yield
    finally:
        app.state.sessions = None
        app.state.passkeys = None
        app.state.sso = None
        app.state.accounts = None


@contextlib.asynccontextmanager
async def follower_sessions(app: FastAPI) -> AsyncIterator[None]:
    """On every process of several (backend/cluster.py): people's sessions read from the
    shared database, for the hub links of pages signed in by their cookie, until this process
    leads and the accounts component's gate takes over. Links opened here stay this gate's:
    its sweep closes them within ``SWEEP_EVERY_S`` of their session ending on any process.
    Nothing is recorded here: signing in and out, and the audit rows, are the leader's REST."""

    def audit(kind: str, _source: str, _data: dict[str, Any]) -> None:
        log.warning("accounts: %r not recorded: the leader records people's actions", kind)

    engine = make_engine(app.state.settings.db_url)
    gate = CookieGate(_service(app, make_sessionmaker(engine), audit))
    app.state.sessions = gate
    try:
        async with _sweeping(gate.service, expire=False):
            yield
    finally:
        if app.state.sessions is gate:
            app.state.sessions = None
        await engine.dispose()
