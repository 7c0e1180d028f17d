"""The hub's WebSocket endpoint (/ws): authenticate, then one reader and one writer per client.

The reader hands every frame to ``Hub.receive``. The writer drains the client's outbox and sends
what is queued as one frame: a single message as a JSON object, several as a JSON array. Batching
is what lets one server core feed 1000 robots at 5 Hz to several GUIs.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from fastapi import APIRouter, WebSocket
from starlette.websockets import WebSocketDisconnect

from backend.auth import TokenStore, bearer_token

from .core import (
    CLOSE_FORBIDDEN,
    CLOSE_UNAUTHORIZED,
    Hub,
    RemoteClient,
)

__all__ = ["router"]

log = logging.getLogger(__name__)

router = APIRouter()

_CLOSE_SEND_TIMEOUT = 2.0


@router.websocket("/ws")
async def hub_socket(websocket: WebSocket) -> None:
    """Token in ``Authorization: Bearer`` or ``?token=``; optional ``?name=`` (modules, admin)."""
    hub: Hub = websocket.app.state.hub
    tokens: TokenStore = websocket.app.state.tokens
    token = bearer_token(
        websocket.headers.get("authorization"), websocket.query_params.get("token")
    )
    principal = tokens.lookup(token)
    await websocket.accept()
    if principal is None:
        await websocket.close(CLOSE_UNAUTHORIZED, "missing or unknown bearer token")
        return
    try:
        name = hub.resolve_name(principal.name, principal.role, websocket.query_params.get("name"))
        client = hub.attach(name, principal.role)
    except PermissionError as exc:
        await websocket.close(CLOSE_FORBIDDEN, str(exc))
        return
    writer = asyncio.create_task(_write(websocket, client), name=f"hub-writer-{name}")
    try:
        while True:
            frame = await websocket.receive()
            if frame["type"] == "websocket.disconnect":
                break
            raw = frame.get("text")
            if raw is None:
                raw = frame.get("bytes") or b""
            hub.receive(client, raw)
            if client.close_code is not None:
                break
    except WebSocketDisconnect:
        pass
    finally:
        hub.detach(client)
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(writer, _CLOSE_SEND_TIMEOUT)
        if not writer.done():
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await writer


async def _write(websocket: WebSocket, client: RemoteClient) -> None:
    """Drain the outbox until the client closes; then send the close code and reason, if any."""
    outbox = client.outbox
    batch_max = client.hub.batch_max
    try:
        while True:
            batch = await outbox.get_batch(batch_max)
            if not batch or client.close_code is not None:
                break
            if len(batch) == 1:
                data = batch[0]
            else:
                data = b"[" + b",".join(batch) + b"]"
            await websocket.send_text(data.decode())
    except (WebSocketDisconnect, RuntimeError, OSError) as exc:
        log.debug("hub: writer of %s stopped: %r", client.name, exc)
        return
    if client.close_code is not None:
        with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
            await websocket.close(client.close_code, client.close_reason)
