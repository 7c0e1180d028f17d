"""The hub's WebSocket endpoint (/ws): authenticate, then one reader and one writer per client.

The reader hands every frame to ``Hub.receive``. The writer drains the client's outbox and sends
what is queued as one frame: a single message as a JSON object, several as a JSON array. It
batches only what is already there: a message for an idle client leaves at once; messages that
arrive while the writer waits for its turn on the event loop, or while a send is held up by the
socket's flow control, queue up and leave together in the next frame. So the busier the server,
the more each frame carries, and a quiet server adds no delay. ``hub_linger_ms`` > 0 (default 0)
adds a wait of up to that long for a streaming client (fewer, larger frames, at that latency).
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
            try:
                hub.receive(client, raw)
            except Exception:  # a bug in a handler must not take the connection down
                log.exception("hub: frame from %s failed", client.name)
                client.error("internal_error", "the server failed to handle this frame")
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
    linger = client.hub.linger
    enough = max(1, min(batch_max, outbox.maxsize // 4))
    loop = asyncio.get_running_loop()
    last_send = 0.0
    try:
        while True:
            await outbox.wait()
            if linger > 0:
                since = loop.time() - last_send
                if since < linger:
                    # Streaming: gather what arrives within ``linger`` of the last frame into one
                    # frame, unless a full batch (or a quarter of the queue) is already waiting.
                    await outbox.linger(linger - since, enough)
            batch = outbox.take(batch_max)
            if not batch or client.close_code is not None:
                break
            if len(batch) == 1:
                data = batch[0]
            else:
                data = b"[" + b",".join(batch) + b"]"
            await websocket.send_text(data.decode())
            client.frames_sent += 1
            if linger > 0:
                last_send = loop.time()
    except (WebSocketDisconnect, RuntimeError, OSError) as exc:
        log.debug("hub: writer of %s stopped: %r", client.name, exc)
        return
    if client.close_code is not None:
        with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
            await websocket.close(client.close_code, client.close_reason)
