"""The hub's WebSocket endpoint (/ws): authenticate, then one reader and one writer per client.

The reader hands every frame to ``Hub.receive``. The writer drains the client's outbox and sends
what is queued as one frame: a single message as a JSON object, several as a JSON array. It
batches only what is already there: a message for an idle client leaves at once; messages that
arrive while the writer waits for its turn on the event loop, or while a send is held up by the
socket's flow control, queue up and leave together in the next frame. A client that was sent a
frame in the last ``Hub.streaming_s`` (2 ms) is streaming: its writer lets the loop turn once more
before it takes the batch, so one frame carries what every robot's reader routed in that turn
(at 1000 robots x 5 Hz: 40 % fewer frames, about 10 % less server CPU, and a lower median
latency, since the server waits less for the CPU). So the busier the server, the more each
frame carries, and a quiet server adds no delay. ``hub_linger_ms`` > 0 (default 0) adds a wait
of up to that long for a streaming client (fewer, larger frames, at that latency).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from fastapi import APIRouter, WebSocket
from starlette.websockets import WebSocketDisconnect

from backend.auth import Authenticator, SignInRefused, bearer_token, client_address
from guidebot import wire

from .core import (
    CLOSE_FORBIDDEN,
    CLOSE_OVERFLOW,
    CLOSE_TOO_MANY_FAILURES,
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
    auth: Authenticator = websocket.app.state.auth
    token = bearer_token(
        websocket.headers.get("authorization"), websocket.query_params.get("token")
    )
    await websocket.accept()
    try:
        principal = auth.authenticate(token, client_address(websocket.client))
    except SignInRefused as exc:
        code = CLOSE_TOO_MANY_FAILURES if exc.status_code == 429 else CLOSE_UNAUTHORIZED
        await websocket.close(code, exc.reason)
        return
    try:
        name = hub.resolve_name(principal.name, principal.role, websocket.query_params.get("name"))
        client = hub.attach(name, principal.role)
    except PermissionError as exc:
        await websocket.close(CLOSE_FORBIDDEN, str(exc))
        return
    writer = asyncio.create_task(_write(websocket, client), name=f"hub-writer-{name}")
    reader = asyncio.create_task(_read(websocket, hub, client), name=f"hub-reader-{name}")
    stall = websocket.app.state.settings.hub_send_timeout_s
    watchdog = asyncio.create_task(_watch_stall(client, stall), name=f"hub-stall-{name}")
    closing = asyncio.create_task(client.closing.wait(), name=f"hub-closing-{name}")
    try:
        # Ends when the client goes, or when the hub stops routing to it (overflow, replaced,
        # shutdown, not reading): a client that never reads is not kept until a keepalive.
        await asyncio.wait({reader, closing, watchdog}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        hub.detach(client)
        for task in (reader, closing, watchdog):
            task.cancel()
        await asyncio.gather(reader, closing, watchdog, return_exceptions=True)
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(asyncio.shield(writer), _CLOSE_SEND_TIMEOUT)
        if not writer.done():
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await writer


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


async def _watch_stall(client: RemoteClient, timeout: float) -> None:
    """Close a client whose queued messages have not moved for ``timeout`` seconds: it does
    not read (its socket buffers are full), so nothing we queue will ever reach it."""
    outbox = client.outbox
    period = min(1.0, timeout / 4)
    taken = outbox.queued - len(outbox)
    still_since: float | None = None
    loop = asyncio.get_running_loop()
    while client.close_code is None:
        await asyncio.sleep(period)
        now_taken = outbox.queued - len(outbox)
        if len(outbox) == 0 or now_taken != taken:
            taken, still_since = now_taken, None
            continue
        if still_since is None:
            still_since = loop.time()
        elif loop.time() - still_since >= timeout:
            client.hub.overflow_disconnects += 1
            client.request_close(CLOSE_OVERFLOW, f"slow consumer: nothing read for {timeout:g} s")
            return


async def _write(websocket: WebSocket, client: RemoteClient) -> None:
    """Drain the outbox until the client closes; then send the close code and reason, if any."""
    outbox = client.outbox
    hub = client.hub
    batch_max = hub.batch_max
    linger = hub.linger
    enough = max(1, min(batch_max, outbox.maxsize // 4))
    loop = asyncio.get_running_loop()
    last_send = 0.0
    try:
        while True:
            await outbox.wait()
            since = loop.time() - last_send
            if linger > 0 and since < linger:
                # Streaming: gather what arrives within ``linger`` of the last frame into one
                # frame, unless a full batch (or a quarter of the queue) is already waiting.
                await outbox.linger(linger - since, enough)
            elif since < hub.streaming_s:
                # Streaming, no linger: let the loop turn once, so that what the other clients'
                # readers route in this turn leaves in this frame rather than in the next one.
                await asyncio.sleep(0)
            batch = outbox.take(batch_max)
            if not batch or client.close_code is not None:
                break
            await websocket.send_text(wire.frame(batch).decode())
            client.frames_sent += 1
            last_send = loop.time()
    except (WebSocketDisconnect, RuntimeError, OSError) as exc:
        log.debug("hub: writer of %s stopped: %r", client.name, exc)
        return
    if client.close_code is not None:
        with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
            await websocket.close(client.close_code, client.close_reason)
