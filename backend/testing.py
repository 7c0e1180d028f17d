"""Run a real GuideBot server inside a test's event loop (uvicorn on 127.0.0.1, port 0).

Usage (any team's tests)::

    from backend.settings import Settings
    from backend.testing import running_server

    async def test_something(tmp_path):
        settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db")
        async with running_server(settings) as server:
            server.url        # "http://127.0.0.1:<port>"
            server.ws_url     # "ws://127.0.0.1:<port>/ws"
            server.hub_url    # the hub listener's /ws with hub_ws_port=0 set, else ws_url
            server.app.state  # hub, tokens, settings, your component's state
            server.admin_token

The context manager waits for uvicorn's ``started`` flag (the lifespan, with every component,
has run), reads the bound port back, and on exit asks uvicorn to stop and waits for it: open
WebSocket connections are closed (code 1012) and the lifespan shutdown runs. Pass ``port=`` to
restart a server on the port of a previous one (reconnect tests).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Generator
from dataclasses import dataclass

import uvicorn
from fastapi import FastAPI

from backend.app import create_app, uvicorn_config
from backend.settings import Settings
from backend.state import app_state

__all__ = ["RunningServer", "running_server"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunningServer:
    app: FastAPI
    server: uvicorn.Server
    host: str
    port: int
    admin_token: str

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://{self.host}:{self.port}/ws"

    @property
    def hub_port(self) -> int:
        """The port hub clients use: the hub's own listener's with ``hub_ws_port`` set, else
        the HTTP port (the /ws route)."""
        listener: int | None = app_state(self.app).hub_ws_port
        return self.port if listener is None else listener

    @property
    def hub_url(self) -> str:
        return f"ws://{self.host}:{self.hub_port}/ws"


class _Server(uvicorn.Server):
    """uvicorn without signal handlers: the test runner owns Ctrl-C."""

    @contextlib.contextmanager
    def capture_signals(self) -> Generator[None, None, None]:
        yield


def _lost_leadership(server: uvicorn.Server) -> None:
    log.error("this in-process server lost its leadership: it stops (a real one exits)")
    server.should_exit = True


async def _serve(server: uvicorn.Server) -> None:
    """uvicorn exits (SystemExit) when its start fails: a SystemExit in a task ends the whole
    event loop, the test's and the servers' cleanup with it; make it a plain error."""
    try:
        await server.serve()
    except SystemExit as exc:
        raise RuntimeError(
            f"uvicorn stopped before it started (exit {exc.code}): see its log"
        ) from None


@contextlib.asynccontextmanager
async def running_server(
    settings: Settings | None = None,
    *,
    port: int = 0,
    app: FastAPI | None = None,
    start_timeout: float = 30.0,
) -> AsyncIterator[RunningServer]:
    """Serve ``create_app(settings)`` (or ``app``) on 127.0.0.1 until the block exits."""
    settings = settings if settings is not None else Settings()
    app = app if app is not None else create_app(settings)
    server = _Server(uvicorn_config(app, "127.0.0.1", port))
    # A leader that loses its lease exits its process at once (backend/cluster.py): here that
    # process is the test runner's, which died with it ("node down"); this server stops instead.
    app.state.on_lost_leadership = lambda: _lost_leadership(server)
    task = asyncio.create_task(_serve(server), name="uvicorn")
    loop = asyncio.get_running_loop()
    deadline = loop.time() + start_timeout
    while not server.started:
        if task.done():
            task.result()  # raises the start-up error
            raise RuntimeError("uvicorn stopped before it started (port in use?)")
        if loop.time() > deadline:
            server.should_exit = True
            await task
            raise TimeoutError(f"server did not start within {start_timeout} s")
        await asyncio.sleep(0.01)
    bound = server.servers[0].sockets[0].getsockname()[1]
    try:
        yield RunningServer(app, server, "127.0.0.1", bound, settings.admin_token)
    finally:
        server.should_exit = True
        await task
