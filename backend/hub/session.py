"""What a hub connection does, whichever listener serves its socket: admit, write, watch.

Two listeners carry hub clients with the same protocol (docs/protocol.md "Connecting"): the /ws
route of the FastAPI app (websocket.py, through uvicorn and ASGI) and the hub's own listener on
``hub_ws_port`` (listener.py, picows). Both admit a client, write its outbox and close it here,
so that sign-in, names, batching and close codes cannot drift apart between them.

Writing batches only what is already there: a message for an idle client leaves at once;
messages that arrive while the writer waits for its turn on the event loop, or while a send is
held up by the socket's flow control, queue up and leave together in the next frame. A client
that was sent a frame in the last ``Hub.streaming_s`` (2 ms) is streaming: its writer lets the
loop turn once more before it takes the batch, so one frame carries what every robot's reader
routed in that turn (at 1000 robots x 5 Hz: 40 % fewer frames, about 10 % less server CPU, and a
lower median latency, since the server waits less for the CPU). So the busier the server, the
more each frame carries, and a quiet server adds no delay. ``hub_linger_ms`` > 0 (default 0)
adds a wait of up to that long for a streaming client (fewer, larger frames, at that latency).

Large messages (``LARGE_FRAME_BYTES``, a site for the robots) leave one per turn of the event
loop: writing one hands megabytes to the socket, about a millisecond, and a publish wakes every
robot's writer in the same turn (20 robots: the loop held 11-25 ms by the site's sends alone).
Batches of many small messages are not held back: a streaming client would fall behind.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable

from backend.auth import Authenticator, Principal, SignInRefused
from guidebot import wire

from .core import (
    CLOSE_FORBIDDEN,
    CLOSE_OVERFLOW,
    CLOSE_TOO_MANY_FAILURES,
    CLOSE_UNAUTHORIZED,
    Hub,
    RemoteClient,
)

__all__ = [
    "CLOSE_SEND_TIMEOUT_S",
    "LARGE_FRAME_BYTES",
    "Refused",
    "SendFrame",
    "admit",
    "serve_client",
    "watch_stall",
    "write_batches",
]

log = logging.getLogger(__name__)

CLOSE_SEND_TIMEOUT_S = 2.0
"""How long a closing connection's writer may take to hand over what is queued, and then how
long the peer has to answer the close frame, before the socket is dropped."""

LARGE_FRAME_BYTES = 256 * 1024
"""A frame of one message at least this long waits for its turn: one per turn of the loop."""

SendFrame = Callable[[bytes], Awaitable[None]]
"""Send one frame of UTF-8 JSON text; waits while the socket's flow control holds it up."""


class Refused(Exception):
    """A connection the hub does not take: close it with ``code`` and ``reason``."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


def admit(
    hub: Hub,
    auth: Authenticator,
    token: str | None,
    address: str,
    requested_name: str | None,
    principal: Principal | None = None,
) -> RemoteClient:
    """Sign a connection in and attach it to the hub (its welcome is queued), or raise Refused:
    4001 unknown token, 4029 too many failures from ``address``, 4003 a name not allowed.

    Each 4001 and 4003 is logged as a warning (address and reason, never the token): the
    failure limit per address bounds how many lines one address can cause. A 4029 (an address
    already locked out) is logged at debug level only. ``principal``: already signed in (a
    person's session cookie, backend/accounts), no token needed."""
    try:
        if principal is None:
            principal = auth.authenticate(token, address)
    except SignInRefused as exc:
        if exc.status_code == 429:
            log.debug("hub: sign-in refused from %s: 4029 %s", address, exc.reason)
            raise Refused(CLOSE_TOO_MANY_FAILURES, exc.reason) from exc
        log.warning("hub: sign-in refused from %s: 4001 %s", address, exc.reason)
        raise Refused(CLOSE_UNAUTHORIZED, exc.reason) from exc
    try:
        name = hub.resolve_name(principal.name, principal.role, requested_name)
        return hub.attach(name, principal.role)
    except PermissionError as exc:
        log.warning(
            "hub: sign-in refused from %s (token of %r): 4003 %s", address, principal.name, exc
        )
        raise Refused(CLOSE_FORBIDDEN, str(exc)) from exc


async def serve_client(
    client: RemoteClient, send: SendFrame, gone: Awaitable[object], stall_timeout: float
) -> bool:
    """Write the client's outbox until it goes (``gone`` completes) or the hub stops routing to
    it (overflow, replaced, shutdown, not reading for ``stall_timeout`` s); then detach it and
    give its writer ``CLOSE_SEND_TIMEOUT_S`` to hand over what is queued. True when the writer
    finished cleanly, so the caller may send the close frame (code and reason on ``client``)."""
    name = client.name
    writer = asyncio.create_task(write_batches(client, send), name=f"hub-writer-{name}")
    ended = asyncio.ensure_future(gone)
    watchdog = asyncio.create_task(watch_stall(client, stall_timeout), name=f"hub-stall-{name}")
    closing = asyncio.create_task(client.closing.wait(), name=f"hub-closing-{name}")
    try:
        # A client that never reads is not kept until a keepalive: the watchdog ends it.
        await asyncio.wait({ended, closing, watchdog}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        client.hub.detach(client)
        for task in (ended, closing, watchdog):
            task.cancel()
        await asyncio.gather(ended, closing, watchdog, return_exceptions=True)
        await asyncio.wait({writer}, timeout=CLOSE_SEND_TIMEOUT_S)
        if not writer.done():
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await writer
    if writer.cancelled():
        return False
    if (failure := writer.exception()) is not None:
        log.debug("hub: writer of %s stopped: %r", name, failure)
        return False
    return True


async def write_batches(client: RemoteClient, send: SendFrame) -> None:
    """Drain the client's outbox, one frame per batch, until the hub stops routing to it."""
    outbox = client.outbox
    hub = client.hub
    batch_max = hub.batch_max
    linger = hub.linger
    enough = max(1, min(batch_max, outbox.maxsize // 4))
    loop = asyncio.get_running_loop()
    last_send = 0.0
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
            return
        frame = wire.frame(batch)
        if len(batch) == 1 and len(frame) >= LARGE_FRAME_BYTES:
            # Wait for a turn of the loop no other large message is written in. The send itself
            # is outside the lock: a client slow to read must not hold up the others.
            async with hub.large_frames:
                await asyncio.sleep(0)
        await send(frame)
        client.frames_sent += 1
        last_send = loop.time()


async def watch_stall(client: RemoteClient, timeout: float) -> None:
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
