"""The hub's WebSocket route (/ws) on the server's HTTP port: one reader task per client.

uvicorn parses the frames and hands them over through ASGI; the reader passes each one to
``Hub.receive``. Admission, the writer and the close codes are session.py's, shared with the
hub's own listener (listener.py), which carries the same protocol without ASGI.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import Any

from fastapi import APIRouter, WebSocket
from starlette.websockets import WebSocketDisconnect

from backend.auth import Authenticator, bearer_token, client_address
from backend.state import app_state

from .core import Hub, RemoteClient
from .session import Refused, admit, serve_client

__all__ = ["router"]

log = logging.getLogger(__name__)

router = APIRouter()


@router.websocket("/ws")
async def hub_socket(websocket: WebSocket) -> None:
    """Token in ``Authorization: Bearer`` or ``?token=``, else a person's session cookie (a
    page of this server's origin only); optional ``?name=`` (modules, admin)."""
    hub: Hub = websocket.app.state.hub
    auth: Authenticator = websocket.app.state.auth
    query = websocket.query_params
    token = bearer_token(websocket.headers.get("authorization"), query.get("token"))
    sessions: Any = app_state(websocket.app).sessions  # narrowed by hand below (session)
    session = None
    if token is None and sessions is not None:
        session = await sessions.websocket_session(websocket)
    await websocket.accept()
    try:
        client = admit(
            hub,
            auth,
            token,
            client_address(websocket.client),
            query.get("name"),
            session.principal if session is not None else None,
        )
    except Refused as exc:
        await websocket.close(exc.code, exc.reason)
        return
    if session is not None:
        sessions.link(session, client)  # closed when the session ends

    async def send(frame: bytes) -> None:
        await websocket.send_text(frame.decode())

    stall = websocket.app.state.settings.hub_send_timeout_s
    try:
        if await serve_client(client, send, _read(websocket, hub, client), stall):
            if client.close_code is not None:
                with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
                    await websocket.close(client.close_code, client.close_reason)
    finally:
        if session is not None:
            sessions.unlink(session, client)


async def _read(websocket: WebSocket, hub: Hub, client: RemoteClient) -> None:
    """Hand every frame to the hub until the client disconnects."""
    with contextlib.suppress(WebSocketDisconnect):
        while True:
            frame = await websocket.receive()
            if frame["type"] == "websocket.disconnect":
                return
            raw = frame.get("text")
            if raw is None:
                raw = frame.get("bytes") or b""
            try:
                hub.receive(client, raw)
            except Exception:  # a bug in a handler must not take the connection down
                log.exception("hub: frame from %s failed", client.name)
                client.error("internal_error", "the server failed to handle this frame")
            if client.close_code is not None:
                return
            # Frames already received are handed over without suspending: give the other
            # clients their turn after each one, so one client's flood cannot hog the loop.
            await asyncio.sleep(0)
