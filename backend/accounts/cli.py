"""``guidebot users``: people's accounts from the command line, for the first admin (before
anyone can sign in to the console) and for an admin locked out. It writes the database of
the server's settings (``GUIDEBOT_DB_URL`` or ``--db-url``) and prints nothing secret: a
password is asked for (hidden, twice) or read from standard input, never echoed."""

from __future__ import annotations

import asyncio
import sys
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import click
from pydantic import ValidationError

from backend.accounts.service import AccountError, AccountService
from backend.accounts.store import AccountStore
from backend.auth import PERSON_ROLES
from backend.ratelimit import RateLimiter

__all__ = ["users"]

T = TypeVar("T")
ROLES = sorted(r.value for r in PERSON_ROLES)
BY = "cli"
"""Who the event log says made a change from the command line."""


def _run(db_url: str | None, work: Callable[[AccountService], Awaitable[T]]) -> T:
    from backend.db import DbStore, make_engine, make_sessionmaker, migrate
    from backend.settings import Settings, describe_errors

    try:
        overrides: dict[str, Any] = {"db_url": db_url} if db_url else {}
        settings = Settings(**overrides)
    except ValidationError as exc:
        raise click.UsageError(describe_errors(exc)) from None

    async def main() -> T:
        engine = make_engine(settings.db_url)
        try:
            await migrate(engine)
            events = DbStore(make_sessionmaker(engine))

            def audit(kind: str, source: str, data: dict[str, Any]) -> None:
                events.record_event(kind, source, data)

            service = AccountService(
                AccountStore(events.sessionmaker),
                failures=RateLimiter(per_minute=0, burst=1),
                lockouts=RateLimiter(per_minute=0, burst=1),
                audit=audit,
                idle_s=settings.session_idle_minutes * 60,
                max_s=settings.session_max_hours * 3600,
                min_length=settings.password_min_length,
                reserved=lambda: {"admin", "hub", "console"} | {t.name for t in settings.tokens},
            )
            result = await work(service)
            await events.flush()
            return result
        finally:
            await engine.dispose()

    try:
        return asyncio.run(main())
    except AccountError as exc:
        raise click.ClickException(exc.reason) from None


def _password(from_stdin: bool) -> str:
    if from_stdin:
        return sys.stdin.readline().rstrip("\r\n")
    return str(click.prompt("Password", hide_input=True, confirmation_prompt=True))


_db = click.option("--db-url", default=None, help="The database (default: GUIDEBOT_DB_URL).")
_stdin = click.option(
    "--password-stdin", is_flag=True, help="Read the password from standard input (one line)."
)


@click.group()
def users() -> None:
    """People's accounts: the first admin, and help for an admin locked out."""


@users.command("add")
@click.argument("name")
@click.option("--role", type=click.Choice(ROLES), default="admin", show_default=True)
@click.option("--display-name", default="", help="The name the console shows.")
@_stdin
@_db
def add(name: str, role: str, display_name: str, password_stdin: bool, db_url: str | None) -> None:
    """Create account NAME (the first admin: `guidebot users add alice`)."""
    password = _password(password_stdin)
    account = _run(
        db_url,
        lambda s: s.create(name, role, password, display_name, by=BY, address="command line"),
    )
    click.echo(f"account {account.name} ({account.role}) created")


@users.command("password")
@click.argument("name")
@_stdin
@_db
def password(name: str, password_stdin: bool, db_url: str | None) -> None:
    """Set a new password for NAME (its sessions end)."""
    secret = _password(password_stdin)
    _run(db_url, lambda s: s.reset_password(name, secret, by=BY, address="command line"))
    click.echo(f"password of {name} set; its sessions ended")


@users.command("enable")
@click.argument("name")
@_db
def enable(name: str, db_url: str | None) -> None:
    """Enable NAME again (an admin disabled by mistake)."""
    _run(db_url, lambda s: s.change(name, disabled=False, by=BY, address="command line"))
    click.echo(f"account {name} enabled")


@users.command("list")
@_db
def list_accounts(db_url: str | None) -> None:
    """Every account: name, role, disabled, last sign-in (UTC)."""

    async def everyone(service: AccountService) -> list[Any]:
        return await service.store.all()

    for account in _run(db_url, everyone):
        last = account.last_sign_in
        when = time.strftime("%Y-%m-%d %H:%M", time.gmtime(last)) if last else "never"
        state = " disabled" if account.disabled else ""
        click.echo(f"{account.name}\t{account.role}{state}\tlast sign-in {when}")
