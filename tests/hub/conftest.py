"""A real server on 127.0.0.1 (ephemeral port) with one token per role, and hub clients."""

from __future__ import annotations

import socket
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest
import websockets
from websockets.asyncio.client import ClientConnection

import backend.app
from backend.auth import Role
from backend.settings import Settings, StaticToken
from backend.testing import RunningServer, running_server
from guidebot.client import HubClient

TOKENS = {
    "R1": StaticToken(token="token-robot-R1", name="R1", role=Role.ROBOT),
    "R2": StaticToken(token="token-robot-R2", name="R2", role=Role.ROBOT),
    "gui": StaticToken(token="token-gui-admin-page", name="gui", role=Role.GUI),
    "tm": StaticToken(token="token-module-tours", name="tour_module", role=Role.MODULE),
    "op": StaticToken(token="token-operator-ann", name="ann", role=Role.OPERATOR),
    "panel": StaticToken(token="token-panel-kiosk", name="kiosk", role=Role.PANEL),
}


LISTENERS = ("asgi", "picows")
"""Where hub clients connect: /ws through uvicorn, or the hub's own listener (hub_ws_port)."""


def hub_settings(listener: str = "asgi", **overrides: Any) -> Settings:
    """The test tokens; with ``listener="picows"`` the hub's own listener on a free port."""
    if listener == "picows":
        overrides.setdefault("hub_ws_port", 0)
    return Settings(tokens=list(TOKENS.values()), **overrides)


@pytest.fixture(autouse=True)
def hub_only(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """These tests exercise the hub alone: no server components, no database in the cwd."""
    monkeypatch.setattr(backend.app, "COMPONENTS", [])
    monkeypatch.setenv("GUIDEBOT_DB_URL", f"sqlite+aiosqlite:///{tmp_path}/hub.db")


@pytest.fixture(params=LISTENERS)
def listener(request: pytest.FixtureRequest) -> str:
    """Each hub test runs over both listeners: the protocol is the same on either."""
    return str(request.param)


@pytest.fixture
async def server(listener: str) -> AsyncIterator[RunningServer]:
    async with running_server(hub_settings(listener)) as running:
        yield running


ClientFactory = Callable[..., Awaitable[HubClient]]


@pytest.fixture
async def connect(server: RunningServer) -> AsyncIterator[ClientFactory]:
    """``await connect("R1")``: a connected HubClient with that token, closed after the test."""
    clients: list[HubClient] = []

    async def factory(who: str, **kwargs: Any) -> HubClient:
        token = TOKENS[who].token if who in TOKENS else who
        client = HubClient(server.hub_url, token, **kwargs)
        await client.start()
        clients.append(client)
        return client

    yield factory
    for client in reversed(clients):
        await client.close()


async def never_reading_client(server: RunningServer, token: str) -> ClientConnection:
    """A WebSocket client with a tiny receive buffer that stops reading once asked: after its
    welcome, the kernel buffers between it and the server fill and the server's sends block."""
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", server.hub_port))
    client = await websockets.connect(
        server.hub_url,
        sock=sock,
        additional_headers={"Authorization": f"Bearer {token}"},
        proxy=None,
        compression=None,
        max_queue=1,
        max_size=None,
    )
    await client.recv()  # welcome
    return client
