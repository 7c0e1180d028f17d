"""The session cookie on requests and WebSockets: who it signs in, the CSRF check of every
state-changing request, the cookie's attributes (HttpOnly, SameSite=Strict, Secure outside
development)."""

from __future__ import annotations

import secrets
from urllib.parse import urlsplit

from fastapi import HTTPException, Request, Response, WebSocket, status
from starlette.requests import HTTPConnection

from backend.accounts.service import AccountService, Session
from backend.auth import Principal
from backend.hub.core import RemoteClient

__all__ = [
    "CSRF_HEADER",
    "SAFE_METHODS",
    "SESSION_COOKIE",
    "CookieGate",
    "clear_cookie",
    "set_cookie",
]

SESSION_COOKIE = "guidebot_session"
CSRF_HEADER = "X-CSRF-Token"
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


def same_origin(connection: HTTPConnection) -> bool:
    """False when the browser says the page came from another site (its ``Origin`` is not
    this host): a cross-site WebSocket or form must not ride on the cookie."""
    origin = connection.headers.get("origin")
    if origin is None:
        return True  # not a browser's cross-origin request (browsers send Origin on those)
    return urlsplit(origin).netloc == connection.headers.get("host", "")


class CookieGate:
    """``app.state.sessions`` (backend.auth.SessionGate): a request's session principal."""

    def __init__(self, service: AccountService) -> None:
        self.service = service

    async def session(self, connection: HTTPConnection) -> Session | None:
        cookie = connection.cookies.get(SESSION_COOKIE)
        if cookie is None or not same_origin(connection):
            return None
        return await self.service.session(cookie)

    async def __call__(self, request: Request) -> Principal | None:
        session = await self.session(request)
        if session is None:
            return None
        if request.method not in SAFE_METHODS:
            sent = request.headers.get(CSRF_HEADER, "")
            if not secrets.compare_digest(sent.encode(), session.csrf.encode()):
                raise HTTPException(
                    status.HTTP_403_FORBIDDEN,
                    f"missing or wrong CSRF token (header {CSRF_HEADER}): reload the page",
                )
        request.state.session = session
        return session.principal

    async def websocket_session(self, websocket: WebSocket) -> Session | None:
        return await self.session(websocket)

    def link(self, session: Session, client: RemoteClient) -> None:
        """A hub link opened under ``session``: closed when the session ends (this gate's
        service keeps it, whichever gate serves later requests)."""
        self.service.link(session, client)

    def unlink(self, session: Session, client: RemoteClient) -> None:
        self.service.unlink(session.digest, client)


def set_cookie(response: Response, value: str, *, max_age: int, secure: bool) -> None:
    response.set_cookie(
        SESSION_COOKIE,
        value,
        max_age=max_age,
        path="/",
        httponly=True,
        samesite="strict",
        secure=secure,
    )


def clear_cookie(response: Response, *, secure: bool) -> None:
    response.delete_cookie(
        SESSION_COOKIE, path="/", httponly=True, samesite="strict", secure=secure
    )
