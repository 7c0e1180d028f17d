"""The hub's own WebSocket listener on ``hub_ws_port``: the /ws protocol without ASGI.

uvicorn hands every frame to the app through ASGI: a parse, a queue, a task switch to the
route's reader, Starlette's wrappers, and the same again for every frame sent. At 1000 robots x
5 Hz that is about 0.3 ms of the median and a quarter of the server's CPU (docs/protocol.md
"Measured"). This listener (picows, a
WebSocket server written in Cython) hands each received frame to ``Hub.receive`` from the
callback that parsed it and writes each batch straight to the socket; admission, batching,
the stall watchdog and the close codes are session.py's, the same as /ws. Robots, modules and
integrators that can reach the port use it; web pages keep /ws on the HTTP port.

Differences a client can see (docs/protocol.md "Connecting"): only the path /ws is served (any
other path: HTTP 404); a frame or message over 16 MiB closes with 1009; a dead peer is found by
a ping after 20 s of silence, answered within 20 s (uvicorn's figures).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import deque
from collections.abc import AsyncIterator
from urllib.parse import parse_qs, urlsplit

from fastapi import FastAPI
from picows import (
    WSCloseCode,
    WSFrame,
    WSListener,
    WSMsgType,
    WSTransport,
    WSUpgradeRequest,
    WSUpgradeResponse,
    WSUpgradeResponseWithListener,
    ws_create_server,
)

from backend.auth import bearer_token

from .core import CLOSE_SHUTDOWN, RemoteClient
from .session import CLOSE_SEND_TIMEOUT_S, Refused, admit, serve_client

__all__ = ["MAX_MESSAGE_BYTES", "hub_listener"]

log = logging.getLogger(__name__)

MAX_MESSAGE_BYTES = 16 * 1024 * 1024
"""The largest frame, or message of several frames, the listener reads (uvicorn's limit on /ws)."""

_PING_AFTER_S = 20.0
_DATA = (WSMsgType.TEXT, WSMsgType.BINARY, WSMsgType.CONTINUATION)


class _Connection(WSListener):
    """One hub client over picows: frames in from callbacks, a session task writing out."""

    def __init__(self, listener: _Listener, token: str | None, name: str | None) -> None:
        self.listener = listener
        self.token = token
        self.requested_name = name
        self.transport: WSTransport | None = None
        self.client: RemoteClient | None = None
        self.writable = asyncio.Event()
        self.writable.set()
        self.gone = asyncio.Event()
        """Set when the peer's close frame arrives or the socket ends."""
        self.fragments: list[bytes] | None = None
        """The parts of a message sent in several frames, until its final frame."""
        self.fragments_size = 0
        self.session: asyncio.Task[None] | None = None
        self.held: deque[bytes] = deque()
        """Frames of one read waiting for their turn (reading is paused meanwhile)."""
        self.turn_taken = False
        """A frame of the current read was handed over: the others wait for their turn."""

    # -- picows callbacks (on the event loop, one frame at a time) ---------------------------
    def on_ws_connected(self, transport: WSTransport) -> None:
        self.transport = transport
        peer = transport.underlying_transport.get_extra_info("peername")
        address = str(peer[0]) if peer else "unknown"
        app = self.listener.app
        try:
            self.client = admit(
                app.state.hub, app.state.auth, self.token, address, self.requested_name
            )
        except Refused as exc:
            transport.send_close(WSCloseCode(exc.code), exc.reason.encode())
            transport.disconnect()
            return
        self.session = asyncio.get_running_loop().create_task(
            self._serve(self.client), name=f"hub-listener-{self.client.name}"
        )
        self.listener.connections.add(self)
        self.session.add_done_callback(lambda _: self.listener.connections.discard(self))

    def on_ws_frame(self, transport: WSTransport, frame: WSFrame) -> None:
        kind = frame.msg_type
        if kind is WSMsgType.CLOSE:
            self.gone.set()
            if not transport.is_close_frame_sent:
                code = frame.get_close_code()
                transport.send_close(code if code != WSCloseCode.NO_INFO else WSCloseCode.OK)
            transport.disconnect()
            return
        client = self.client
        if kind in _DATA and client is not None and client.close_code is None:
            if kind is WSMsgType.CONTINUATION or not frame.fin:
                self._gather(transport, frame)
            else:
                self._hand_over(client, frame.get_payload_as_bytes())
        # (pings are answered by picows; pongs need nothing)
        if frame.last_in_buffer:
            self.turn_taken = False  # the next read's first frame is handed over at once

    def on_ws_disconnected(self, transport: WSTransport) -> None:
        self.gone.set()
        self.writable.set()  # a writer waiting for room finds the socket gone, not a hang

    def pause_writing(self) -> None:
        self.writable.clear()

    def resume_writing(self) -> None:
        self.writable.set()

    # -- the rest -----------------------------------------------------------------------------
    def _gather(self, transport: WSTransport, frame: WSFrame) -> None:
        """A message sent in several frames: keep the parts until the final one."""
        starts = frame.msg_type is not WSMsgType.CONTINUATION
        if starts == (self.fragments is not None):  # a new message inside one, or a stray part
            transport.send_close(WSCloseCode.PROTOCOL_ERROR, b"fragments out of order")
            transport.disconnect()
            return
        if starts:
            self.fragments, self.fragments_size = [], 0
        assert self.fragments is not None
        part = frame.get_payload_as_bytes()
        self.fragments.append(part)
        self.fragments_size += len(part)
        if self.fragments_size > MAX_MESSAGE_BYTES:
            transport.send_close(WSCloseCode.MESSAGE_TOO_BIG, b"message larger than 16 MiB")
            transport.disconnect()
            return
        if frame.fin:
            raw, self.fragments = b"".join(self.fragments), None
            if self.client is not None:
                self._hand_over(self.client, raw)

    def _hand_over(self, client: RemoteClient, raw: bytes) -> None:
        """Give a frame to the hub: the first of each read at once, the others of that read
        one per turn of the event loop, so the other clients' readers and writers run between
        them, as /ws reads one frame per turn. Reading stops while frames wait their turn, so
        a client flooding frames is held back by TCP."""
        if not (self.held or self.turn_taken):
            self.turn_taken = True
            self._receive(client, raw)
            return
        if not self.held:  # the first to wait: stop reading; one release runs per turn
            assert self.transport is not None
            self.transport.underlying_transport.pause_reading()
            asyncio.get_running_loop().call_soon(self._release_held)
        self.held.append(raw)

    def _release_held(self) -> None:
        """Hand over the next kept frame; again next turn while any are left, else read on.
        (A release is scheduled exactly while frames are kept.)"""
        self.turn_taken = False
        client, held = self.client, self.held
        if client is None or client.close_code is not None or self.gone.is_set():
            held.clear()  # closing: nothing more is read
            return
        self._receive(client, held.popleft())
        if held:
            asyncio.get_running_loop().call_soon(self._release_held)
        elif self.transport is not None:
            self.transport.underlying_transport.resume_reading()

    def _receive(self, client: RemoteClient, raw: bytes) -> None:
        try:
            client.hub.receive(client, raw)
        except Exception:  # a bug in a handler must not take the connection down
            log.exception("hub: frame from %s failed", client.name)
            client.error("internal_error", "the server failed to handle this frame")

    async def _send(self, frame: bytes) -> None:
        if not self.writable.is_set():
            await self.writable.wait()
        transport = self.transport
        if transport is None or self.gone.is_set():
            raise ConnectionResetError("the client is gone")
        transport.send(WSMsgType.TEXT, frame)

    async def _serve(self, client: RemoteClient) -> None:
        """Serve the client until it goes or the hub closes it; then say why, if it listens."""
        transport = self.transport
        assert transport is not None
        stall = self.listener.app.state.settings.hub_send_timeout_s
        try:
            wrote_all = await serve_client(client, self._send, self.gone.wait(), stall)
        except BaseException:  # cancelled (shutdown ran out of time): drop the socket
            transport.disconnect(graceful=False)
            raise
        if client.close_code is None or self.gone.is_set():
            return  # the client went
        if wrote_all:
            transport.send_close(WSCloseCode(client.close_code), client.close_reason.encode())
            # The peer answers the close frame, then we drop the socket.
            with contextlib.suppress(asyncio.TimeoutError):
                async with asyncio.timeout(CLOSE_SEND_TIMEOUT_S):
                    await self.gone.wait()
        transport.disconnect(graceful=wrote_all)


class _Listener:
    """The picows server and its connections, for a clean shutdown."""

    def __init__(self, app: FastAPI) -> None:
        self.app = app
        self.connections: set[_Connection] = set()
        """Connections admitted and not yet ended (each with its session task)."""

    def route(self, request: WSUpgradeRequest) -> _Connection | WSUpgradeResponseWithListener:
        """Called with the upgrade request: only /ws; the token and name as /ws reads them."""
        target = urlsplit(request.path.decode("latin-1"))
        if target.path != "/ws":
            refusal = WSUpgradeResponse.create_error_response(404, b"the hub is at /ws\n")
            return WSUpgradeResponseWithListener(refusal, None)
        query = parse_qs(target.query)
        token = bearer_token(request.headers.get("authorization"), _first(query, "token"))
        return _Connection(self, token, _first(query, "name"))


def _first(query: dict[str, list[str]], key: str) -> str | None:
    values = query.get(key)
    return values[0] if values else None


@contextlib.asynccontextmanager
async def hub_listener(app: FastAPI, host: str, port: int) -> AsyncIterator[int]:
    """Serve the hub on ``host:port`` (0: any free port) while the block runs; yields the
    bound port. On exit every client is closed with 1001 "server shutting down"."""
    listener = _Listener(app)
    server = await ws_create_server(
        listener.route,
        host,
        port,
        max_frame_size=MAX_MESSAGE_BYTES,
        enable_auto_ping=True,
        auto_ping_idle_timeout=_PING_AFTER_S,
        auto_ping_reply_timeout=_PING_AFTER_S,
        logger_name="backend.hub.listener.picows",
    )
    bound = int(server.sockets[0].getsockname()[1])
    log.info("hub listener on ws://%s:%d/ws", host, bound)
    try:
        yield bound
    finally:
        server.close()
        sessions = {c.session for c in listener.connections if c.session is not None}
        for connection in list(listener.connections):
            if connection.client is not None:
                connection.client.request_close(CLOSE_SHUTDOWN, "server shutting down")
        if sessions:
            await asyncio.wait(sessions, timeout=2 * CLOSE_SEND_TIMEOUT_S + 1)
        for session in sessions:
            session.cancel()
        await server.wait_closed()
