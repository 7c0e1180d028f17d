"""The accounts component (backend.app.COMPONENTS, after the server brain: it needs the
database): ``app.state.accounts`` (the service) and ``app.state.sessions`` (the cookie gate
the token checks consult), and a sweeper ending expired sessions and the hub links of
sessions ended by another server process."""

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
from backend.accounts.service import AccountService
from backend.accounts.store import AccountStore
from backend.ratelimit import RateLimiter

__all__ = ["SWEEP_EVERY_S", "accounts"]

log = logging.getLogger(__name__)

SWEEP_EVERY_S = 5.0


def reserved_names(app: FastAPI) -> set[str]:
    """Names an account may not take: the tokens' and the site's robots' (hub names)."""
    settings = app.state.settings
    names = {"admin", "hub", "console"} | {t.name for t in settings.tokens}
    sites = getattr(app.state, "sites", None)
    if sites is not None:
        names |= {robot.name for robot in sites.site.robots}
    return names


@contextlib.asynccontextmanager
async def accounts(app: FastAPI) -> AsyncIterator[None]:
    settings = app.state.settings
    store = app.state.store

    def audit(kind: str, source: str, data: dict[str, Any]) -> None:
        store.record_event(kind, source[:64], data)

    service = AccountService(
        AccountStore(store.sessionmaker),
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
    app.state.accounts = service
    app.state.passkeys = PasskeyService(service)
    sso = OidcConfig.from_settings(settings)
    app.state.sso = SingleSignOn(sso, service) if sso is not None else None
    app.state.sessions = CookieGate(service)

    async def sweep() -> None:
        while True:
            await asyncio.sleep(SWEEP_EVERY_S)
            try:
                await service.sweep()
            except Exception:
                log.exception("accounts: the session sweep failed; trying again")

    sweeper = asyncio.create_task(sweep(), name="accounts-sweeper")
    try:
        yield
    finally:
        sweeper.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await sweeper
        app.state.sessions = None
        app.state.passkeys = None
        app.state.sso = None
        app.state.accounts = None
