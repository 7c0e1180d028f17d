"""Real receivers for the notification tests, in the test's event loop on 127.0.0.1 port 0: an
SMTP server (aiosmtpd) that keeps what it is handed, and a webhook receiver (uvicorn) that keeps
each POST and answers what the test says. Waits are on events, never on the clock."""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from email import message_from_bytes, policy
from email.message import EmailMessage
from typing import Any, cast

import uvicorn
from aiosmtpd.smtp import SMTP, AuthResult, Envelope, LoginPassword, Session
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Route

__all__ = ["Hooks", "Inbox", "closed_port", "smtp_server", "webhook_receiver"]


class _Changes:
    """Something arrived: waiters look again."""

    def __init__(self) -> None:
        self._changed = asyncio.Condition()

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    async def _until(self, done: Callable[[], bool]) -> None:
        async with self._changed:
            await self._changed.wait_for(done)


class Inbox(_Changes):
    """What the SMTP server accepted: each message parsed, with who signed in for it."""

    def __init__(self, accounts: dict[str, str] | None = None) -> None:
        super().__init__()
        self.port = 0
        self.accounts = accounts or {}
        self.messages: list[EmailMessage] = []
        self.logins: list[str] = []

    async def handle_DATA(self, server: SMTP, session: Session, envelope: Envelope) -> str:
        content = envelope.content if isinstance(envelope.content, bytes) else b""
        message = cast(EmailMessage, message_from_bytes(content, policy=policy.default))
        self.messages.append(message)
        await self._notify()
        return "250 OK queued"

    def authenticate(
        self, server: SMTP, session: Session, envelope: Envelope, mechanism: str, data: Any
    ) -> AuthResult:
        if isinstance(data, LoginPassword):
            user, password = data.login.decode(), data.password.decode()
            if self.accounts.get(user) == password:
                self.logins.append(user)
                return AuthResult(success=True)
        return AuthResult(success=False, handled=False)

    async def wait_for(self, count: int) -> list[EmailMessage]:
        await self._until(lambda: len(self.messages) >= count)
        return self.messages


@contextlib.asynccontextmanager
async def smtp_server(accounts: dict[str, str] | None = None) -> AsyncIterator[Inbox]:
    """An SMTP server without TLS; with ``accounts`` it offers AUTH (LOGIN/PLAIN) and takes
    these users' passwords only."""
    inbox = Inbox(accounts)
    options: dict[str, Any] = {}
    if accounts:
        options = {
            "authenticator": inbox.authenticate,
            "auth_require_tls": False,
        }
    loop = asyncio.get_running_loop()
    server = await loop.create_server(
        lambda: SMTP(inbox, hostname="smtp.test", **options), "127.0.0.1", 0
    )
    inbox.port = server.sockets[0].getsockname()[1]
    try:
        yield inbox
    finally:
        server.close()


@dataclass
class Post:
    path: str
    headers: dict[str, str]
    body: bytes


@dataclass
class Hooks(_Changes):
    """The webhook receiver: every POST kept; ``status`` is what it answers (per path)."""

    port: int = 0
    posts: list[Post] = field(default_factory=list)
    status: dict[str, int] = field(default_factory=dict)
    hang: asyncio.Event | None = None
    """Set: a POST to /hang is held until the event is set (a receiver that does not answer)."""
    hanging: asyncio.Event = field(default_factory=asyncio.Event)

    def __post_init__(self) -> None:
        super().__init__()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def at(self, path: str) -> list[Post]:
        return [p for p in self.posts if p.path == path]

    async def wait_for(self, path: str, count: int) -> list[Post]:
        await self._until(lambda: len(self.at(path)) >= count)
        return self.at(path)

    async def receive(self, request: Request) -> Response:
        path = request.url.path
        post = Post(path, dict(request.headers), await request.body())
        if path == "/hang" and self.hang is not None:
            self.hanging.set()
            await self.hang.wait()
        self.posts.append(post)
        await self._notify()
        return Response(status_code=self.status.get(path, 204))


@contextlib.asynccontextmanager
async def webhook_receiver() -> AsyncIterator[Hooks]:
    hooks = Hooks()
    app = Starlette(routes=[Route("/{path:path}", hooks.receive, methods=["POST"])])
    config = uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", lifespan="off")
    server = uvicorn.Server(config)
    server.capture_signals = contextlib.nullcontext  # type: ignore[method-assign,assignment]
    task = asyncio.create_task(server.serve(), name="webhook-receiver")
    while not server.started:  # uvicorn has no event for it (as backend/testing.py)
        if task.done():
            task.result()
        await asyncio.sleep(0.01)
    hooks.port = server.servers[0].sockets[0].getsockname()[1]
    try:
        yield hooks
    finally:
        if hooks.hang is not None:
            hooks.hang.set()
        server.should_exit = True
        await task


def closed_port() -> int:
    """A port nothing listens on (bound, read, closed): a receiver that is down."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])
