"""Fixtures of the server tests: a real uvicorn server on 127.0.0.1 with the demo site."""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from pathlib import Path

import httpx
import pytest

from backend.auth import Role
from backend.settings import Settings, StaticToken
from backend.tasks import TaskManager
from backend.testing import RunningServer, running_server
from guidebot.bus import Bus
from guidebot.messages import Message

from .helpers import DEMO, demo_site
from .postgres import PostgresServer, postgres_server

PANEL_TOKEN = "panel-token-1234"
OPERATOR_TOKEN = "operator-token-1234"
GUI_TOKEN = "gui-token-12345678"
MODULE_TOKEN = "module-token-12345678"
PERSON_TOKENS = {
    Role.INSTALLER: "installer-token-1234",
    Role.AUTHOR: "author-token-12345678",
    Role.VIEWER: "viewer-token-12345678",
}
"""Tokens of the roles people's accounts have (backend/accounts): the lenient server's."""


def server_settings(tmp_path: Path, db_url: str | None = None) -> Settings:
    return Settings(
        db_url=db_url or f"sqlite+aiosqlite:///{tmp_path / 'guidebot.db'}",
        site=DEMO,
        tokens=[
            StaticToken(token=PANEL_TOKEN, name="panel-1", role=Role.PANEL),
            StaticToken(token=OPERATOR_TOKEN, name="operator-1", role=Role.OPERATOR),
            StaticToken(token=GUI_TOKEN, name="gui-1", role=Role.GUI),
        ],
    )


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    """One real PostgreSQL server on 127.0.0.1 for the session."""
    with postgres_server() as pg:
        yield pg


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """Both databases the server supports: a SQLite file, and an empty PostgreSQL database."""
    if request.param == "sqlite":
        return f"sqlite+aiosqlite:///{tmp_path / 'guidebot.db'}"
    return str(request.getfixturevalue("postgres").database())


@pytest.fixture
async def server(tmp_path: Path) -> AsyncIterator[RunningServer]:
    async with running_server(server_settings(tmp_path)) as srv:
        yield srv


@pytest.fixture
async def lenient(tmp_path: Path) -> AsyncIterator[RunningServer]:
    """The server with a module token too, and failed sign-ins not limited: for tests that
    call every operation with a wrong token (else the 11th answer is 429; a call without a
    token is not a failed sign-in, docs/security.md)."""
    settings = server_settings(tmp_path)
    settings.tokens.append(StaticToken(token=MODULE_TOKEN, name="module-1", role=Role.MODULE))
    for role, token in PERSON_TOKENS.items():
        settings.tokens.append(StaticToken(token=token, name=f"{role.value}-1", role=role))
    settings.sign_in_failure_burst = 1_000_000
    async with running_server(settings) as srv:
        yield srv


ClientFactory = Callable[[str | None], Awaitable[httpx.AsyncClient]]


@pytest.fixture
async def http(server: RunningServer) -> AsyncIterator[Callable[[str | None], httpx.AsyncClient]]:
    clients: list[httpx.AsyncClient] = []

    def make(token: str | None) -> httpx.AsyncClient:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        client = httpx.AsyncClient(base_url=server.url, headers=headers, timeout=10)
        clients.append(client)
        return client

    yield make
    for client in clients:
        await client.aclose()


class Clock:
    """A hand-moved monotonic clock for the Task Manager."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def bus() -> Bus:
    return Bus()


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def events(bus: Bus) -> list[Message]:
    seen: list[Message] = []
    bus.endpoint("monitor").subscribe("task_event", seen.append)
    return seen


@pytest.fixture
async def manager(bus: Bus, clock: Clock) -> AsyncIterator[TaskManager]:
    """A Task Manager over a bare bus with the demo site and short time-outs; no watchdog
    task (the tests drive the clock and call check_timeouts)."""
    tm = TaskManager(
        bus.endpoint("task_manager"),
        demo_site(),
        clock=clock,
        robot_timeout_s=5,
        lost_grace_s=20,
        start_timeout_s=30,
        tick_s=None,
    )
    await tm.start()
    yield tm
    await tm.stop()
