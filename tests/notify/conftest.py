"""A real server with the demo site (no robots) and real receivers, all on 127.0.0.1 port 0."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import httpx
import pytest

from backend.auth import Role
from backend.notify.service import Notifier
from backend.settings import Settings, StaticToken
from backend.testing import RunningServer, running_server
from tests.server.helpers import DEMO

from .receivers import Hooks, Inbox, smtp_server, webhook_receiver

OPERATOR_TOKEN = "operator-token-1234"
VIEWER_TOKEN = "viewer-token-12345678"


def settings(tmp_path: Path) -> Settings:
    return Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path / 'guidebot.db'}",
        site=DEMO,
        tokens=[
            StaticToken(token=OPERATOR_TOKEN, name="operator-1", role=Role.OPERATOR),
            StaticToken(token=VIEWER_TOKEN, name="viewer-1", role=Role.VIEWER),
        ],
    )


@pytest.fixture
async def server(tmp_path: Path) -> AsyncIterator[RunningServer]:
    async with running_server(settings(tmp_path)) as srv:
        notifier: Notifier = srv.app.state.notify
        notifier.retry_delays_s = (0.05, 0.1)  # 3 attempts, quickly
        yield srv


@pytest.fixture
async def admin(server: RunningServer) -> AsyncIterator[httpx.AsyncClient]:
    headers = {"Authorization": f"Bearer {server.admin_token}"}
    async with httpx.AsyncClient(base_url=server.url, headers=headers, timeout=30) as client:
        yield client


@pytest.fixture
async def inbox() -> AsyncIterator[Inbox]:
    async with smtp_server() as box:
        yield box


@pytest.fixture
async def hooks() -> AsyncIterator[Hooks]:
    async with webhook_receiver() as receiver:
        yield receiver
