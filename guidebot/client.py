"""Client library of the JCentral hub: what robot agents, the building simulator and external
modules use to talk to the central server over WebSocket.

``HubClient`` is a ``guidebot.bus.BusEndpoint`` (publish, send, subscribe, subscription,
request), so a module written against the in-process bus runs unchanged against the hub::

    async with HubClient("ws://127.0.0.1:8000/ws", token) as hub:
        hub.subscribe("task_*", on_task)
        reply = await hub.request("get_path", {...}, timeout=2.0)

Behaviour (docs/protocol.md, "Client library"):
- heartbeats: a ``ping`` every ``heartbeat_interval`` (the first one after a random half to
  whole interval, so clients that connected together do not ping together); no frame at all
  for ``heartbeat_timeout`` means the server is dead: the connection is dropped and
  re-established;
- reconnect with exponential back-off (``backoff_initial`` doubling up to ``backoff_max``, with
  jitter); subscriptions are sent again and ``on_connect`` callbacks run after every connection
  (resynchronise there);
- outgoing messages wait in one bounded queue (``queue_size``) while disconnected and are flushed
  in order on reconnect. Overflow rule: a robot_state replaces the queued robot_state of the same
  source; otherwise the oldest queued message is dropped, counted in ``dropped`` and logged;
- close codes 4000 (replaced), 4001 (bad token) and 4003 (forbidden) are final: no reconnect,
  ``failure`` says why.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
import random
from collections.abc import Awaitable, Callable
from typing import Any
from urllib.parse import urlencode, urlsplit, urlunsplit

import orjson
from pydantic import ValidationError
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake

from guidebot import wire
from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.queues import KeyedQueue
from guidebot.routing import Handler, PatternTable, PendingRequests, RequestTimeout, Route

__all__ = ["FINAL_CLOSE_CODES", "HubClient", "HubClosed", "HubError", "HubRefused"]

log = logging.getLogger(__name__)

FINAL_CLOSE_CODES = frozenset({4000, 4001, 4003})
"""Close codes after which reconnecting would not help (or would fight another connection)."""

_COALESCED = frozenset({"robot_state"})
_BATCH_MAX = 256
_BATCH_BYTES = 1 << 18


class HubError(Exception):
    """The hub refused a message (an ``error`` reply); ``code`` is the protocol's error code."""

    def __init__(self, code: str, reason: str) -> None:
        super().__init__(f"{code}: {reason}")
        self.code = code
        self.reason = reason


class HubRefused(ConnectionError):
    """The hub closed the connection for good (bad token, forbidden name, replaced)."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(f"hub closed the connection ({code}): {reason}")
        self.code = code
        self.reason = reason


class HubClosed(ConnectionError):
    """The client was closed, or could not connect in time."""


OnConnect = Callable[[], Awaitable[None] | None]


class HubClient(BusEndpoint):
    """A named client of the hub over WebSocket, with heartbeats and reconnection."""

    def __init__(
        self,
        url: str,
        token: str,
        *,
        name: str | None = None,
        heartbeat_interval: float = 5.0,
        heartbeat_timeout: float = 15.0,
        backoff_initial: float = 0.2,
        backoff_max: float = 10.0,
        queue_size: int = 4096,
        connect_timeout: float | None = 10.0,
        max_size: int = 16 * 1024 * 1024,
    ) -> None:
        if queue_size < 1:
            raise ValueError("queue_size must be at least 1")
        self.url = url
        self.name = name or ""
        self.role = ""
        self.heartbeat_interval = heartbeat_interval
        self.heartbeat_timeout = heartbeat_timeout
        self.backoff_initial = backoff_initial
        self.backoff_max = backoff_max
        self.queue_size = queue_size
        self.connect_timeout = connect_timeout
        self.connected = asyncio.Event()
        self.failure: HubRefused | None = None
        self.last_error: HubError | None = None
        self.connections = 0
        self._token = token
        self._requested_name = name
        self._max_size = max_size
        self._routes: PatternTable[Route] = PatternTable()
        self._pending = PendingRequests()
        self._on_connect: list[OnConnect] = []
        self._on_disconnect: list[Callable[[], None]] = []
        self._out: KeyedQueue[bytes] = KeyedQueue(
            queue_size, drop_oldest=True, name=f"hub client {name or url}: send queue"
        )
        self._ws: ClientConnection | None = None
        self._runner: asyncio.Task[None] | None = None
        self._closing = False
        self._last_seen = 0.0

    @property
    def dropped(self) -> int:
        """Messages dropped from the full send queue (oldest first) while disconnected."""
        return self._out.dropped

    # -- life cycle ---------------------------------------------------------------------------
    async def __aenter__(self) -> HubClient:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def start(self) -> None:
        """Start connecting; waits ``connect_timeout`` for the first connection (None: no wait)."""
        if self._runner is None:
            self._runner = asyncio.create_task(self._run(), name=f"hub-client-{self.name}")
        if self.connect_timeout is None:
            return
        done = asyncio.ensure_future(self.connected.wait())
        try:
            await asyncio.wait(
                {done, self._runner},
                timeout=self.connect_timeout,
                return_when=asyncio.FIRST_COMPLETED,
            )
        finally:
            done.cancel()
        if not self.connected.is_set():
            failure = self.failure
            await self.close(flush=False)
            if failure is not None:
                raise failure
            raise HubClosed(f"no connection to {self.url} within {self.connect_timeout} s")

    async def close(self, *, flush: bool = True, flush_timeout: float = 2.0) -> None:
        """Send what is queued (if connected, up to ``flush_timeout``), then disconnect."""
        if flush and self.connected.is_set() and len(self._out):
            with contextlib.suppress(TimeoutError, RequestTimeout, HubError):
                await self.sync(timeout=flush_timeout)
        self._closing = True
        ws = self._ws
        if ws is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(ws.close(), flush_timeout)
        runner, self._runner = self._runner, None
        if runner is not None:
            runner.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await runner
        self._pending.cancel_all()
        self.connected.clear()

    async def wait_stopped(self) -> HubRefused | None:
        """Wait until the client stops for good (closed, or refused: then the refusal)."""
        runner = self._runner
        if runner is not None:
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.shield(runner)
        return self.failure

    def on_disconnect(self, callback: Callable[[], None]) -> Callable[[], None]:
        """Call ``callback`` when an established connection is lost (the link is down)."""
        self._on_disconnect.append(callback)
        return lambda: (
            self._on_disconnect.remove(callback) if callback in self._on_disconnect else None
        )

    def on_connect(self, callback: OnConnect) -> Callable[[], None]:
        """Run ``callback`` after every (re)connection, subscriptions already restored."""
        self._on_connect.append(callback)
        return lambda: self._on_connect.remove(callback) if callback in self._on_connect else None

    # -- BusEndpoint ----------------------------------------------------------------------------
    def _transmit(self, message: Message) -> None:
        self._enqueue(message)

    def subscribe(self, pattern: str, handler: Handler) -> Callable[[], None]:
        """Call ``handler`` for messages whose type matches; returns the unsubscribe function.

        The subscription reaches the hub asynchronously; ``await sync()`` to know it is active.
        Messages addressed to this client arrive whether or not a pattern matches them, but
        only handlers whose pattern matches are called. Replies that complete a ``request`` and
        the hub's heartbeat pongs are not passed to handlers.
        """
        route = Route(pattern, handler)
        if self._routes.add(route) and self.connected.is_set():
            self._control("subscribe", [pattern])
        removed = False

        def unsubscribe() -> None:
            nonlocal removed
            if removed:
                return
            removed = True
            if self._routes.remove(route) and self.connected.is_set():
                self._control("unsubscribe", [pattern])

        return unsubscribe

    def _check_reply(self, reply: Message) -> Message:
        """A request refused by the hub (an ``error`` reply) raises HubError."""
        if reply.type == "error" and reply.source == "hub":
            raise HubError(str(reply.payload.get("code")), str(reply.payload.get("reason")))
        return reply

    async def sync(self, timeout: float = 5.0) -> None:
        """Round trip through the hub: everything sent before (subscriptions too) is applied."""
        await self.request("ping", timeout=timeout)

    # -- outgoing queue -------------------------------------------------------------------------
    def _enqueue(self, message: Message) -> None:
        if self._closing:
            raise HubClosed("the hub client is closed")
        # Coalesce only while offline: when connected every state is sent (seq has no gaps).
        coalesce = message.type in _COALESCED and not self.connected.is_set()
        self._out.put(wire.encode(message), message.source if coalesce else None)

    def _control(self, type: str, patterns: list[str]) -> None:
        self._enqueue(Message(type=type, source=self.name, payload={"patterns": patterns}))

    async def _writer(self, ws: ClientConnection) -> None:
        out = self._out
        while True:
            await out.wait()
            batch = out.take_entries(_BATCH_MAX, _BATCH_BYTES)
            try:
                await ws.send(wire.frame([entry[1] for entry in batch]), text=True)
            except BaseException:
                out.requeue(batch)  # not sent: the next connection sends them, in order
                raise

    # -- connection -----------------------------------------------------------------------------
    def _connect_url(self) -> str:
        if not self._requested_name:
            return self.url
        parts = urlsplit(self.url)
        query = "&".join(q for q in (parts.query, urlencode({"name": self._requested_name})) if q)
        return urlunsplit(parts._replace(query=query))

    async def _run(self) -> None:
        delay = self.backoff_initial
        while not self._closing:
            try:
                ws = await connect(
                    self._connect_url(),
                    additional_headers={"Authorization": f"Bearer {self._token}"},
                    compression=None,
                    proxy=None,
                    ping_interval=None,
                    open_timeout=max(self.heartbeat_timeout, 5.0),
                    close_timeout=2.0,
                    max_size=self._max_size,
                )
            except (OSError, InvalidHandshake, TimeoutError) as exc:
                log.info("hub %s unreachable (%r); retrying in %.1f s", self.url, exc, delay)
            else:
                try:
                    welcomed = await self._session(ws)
                except HubRefused as exc:
                    self.failure = exc
                    log.error("%s", exc)
                    return
                if welcomed:
                    delay = self.backoff_initial
            if self._closing:
                return
            await asyncio.sleep(delay * random.uniform(0.8, 1.2))
            delay = min(delay * 2, self.backoff_max)

    async def _session(self, ws: ClientConnection) -> bool:
        """One connection: welcome, resubscribe, then read until it drops. True if welcomed."""
        self._ws = ws
        loop = asyncio.get_running_loop()
        tasks: list[asyncio.Task[None]] = []
        try:
            first = await asyncio.wait_for(ws.recv(), self.heartbeat_timeout)
            welcome = orjson.loads(first)
            # What the hub's modules send a client as it connects (closures, booked tours,
            # the fleet's service to a robot) may leave in the welcome's own frame.
            along: list[Any] = []
            if isinstance(welcome, list) and welcome:
                welcome, along = welcome[0], welcome[1:]
            if not isinstance(welcome, dict) or welcome.get("type") != "welcome":
                raise ConnectionError(f"expected welcome, got {first[:200]!r}")
            self.name = welcome["payload"]["name"]
            self.role = welcome["payload"]["role"]
            self._last_seen = loop.time()
            patterns = self._routes.patterns()
            if patterns:
                sub = Message(type="subscribe", source=self.name, payload={"patterns": patterns})
                await ws.send(wire.encode(sub), text=True)
            self.connections += 1
            self.connected.set()
            for item in along:
                self._dispatch(item)
            tasks = [
                asyncio.create_task(self._writer(ws), name=f"hub-writer-{self.name}"),
                asyncio.create_task(self._heartbeat(ws), name=f"hub-heartbeat-{self.name}"),
            ]
            for callback in list(self._on_connect):
                tasks.append(asyncio.create_task(self._run_callback(callback)))
            with contextlib.suppress(ConnectionClosed):
                await self._read(ws, tasks[:2])
            self._check_close(ws)
            return True
        except ConnectionClosed:
            self._check_close(ws)
            return False
        except HubRefused:
            raise
        except (OSError, TimeoutError, ConnectionError, ValueError) as exc:
            log.warning("%s: hub session failed: %r", self.name or "client", exc)
            return False
        finally:
            was_connected = self.connected.is_set()
            self.connected.clear()
            self._ws = None
            if was_connected:
                for callback in list(self._on_disconnect):
                    try:
                        callback()
                    except Exception:
                        log.exception("%s: on_disconnect callback failed", self.name)
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(BaseException):
                    await task
            if ws.transport is not None:
                ws.transport.abort()

    def _check_close(self, ws: ClientConnection) -> None:
        """Raise HubRefused if the hub closed with a final code; otherwise log and go on."""
        rcvd = ws.protocol.close_rcvd
        code = rcvd.code if rcvd is not None else None
        reason = rcvd.reason if rcvd is not None else ""
        if code in FINAL_CLOSE_CODES:
            raise HubRefused(code, reason)
        if not self._closing:
            log.warning("%s: connection to the hub lost (%s %s)", self.name, code, reason)

    async def _read(self, ws: ClientConnection, workers: list[asyncio.Task[None]]) -> None:
        loop = asyncio.get_running_loop()
        receiver = asyncio.ensure_future(self._receive_loop(ws, loop))
        try:
            done, _ = await asyncio.wait({receiver, *workers}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            receiver.cancel()
            with contextlib.suppress(BaseException):
                await receiver
        for task in done:
            if not task.cancelled() and task.exception() is not None:
                raise task.exception()  # type: ignore[misc]
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(ws.wait_closed(), 2.0)

    async def _receive_loop(self, ws: ClientConnection, loop: asyncio.AbstractEventLoop) -> None:
        async for frame in ws:
            self._last_seen = loop.time()
            try:
                data = orjson.loads(frame)
            except orjson.JSONDecodeError:
                log.warning("%s: hub sent a frame that is not JSON", self.name)
                continue
            if isinstance(data, list):
                for item in data:
                    self._dispatch(item)
            else:
                self._dispatch(data)

    async def _heartbeat(self, ws: ClientConnection) -> None:
        loop = asyncio.get_running_loop()
        # The first ping comes after a random half to whole interval: clients that connected
        # together (a fleet after a server restart) do not all ping in the same instant.
        delay = self.heartbeat_interval * random.uniform(0.5, 1.0)
        while True:
            await asyncio.sleep(delay)
            delay = self.heartbeat_interval
            if loop.time() - self._last_seen > self.heartbeat_timeout:
                log.warning(
                    "%s: no frame from the hub for %.1f s: dropping the connection",
                    self.name,
                    loop.time() - self._last_seen,
                )
                ws.transport.abort()
                return
            self._enqueue(Message(type="ping", source=self.name))

    async def _run_callback(self, callback: OnConnect) -> None:
        try:
            result = callback()
            if inspect.isawaitable(result):
                await result
        except Exception:
            log.exception("%s: on_connect callback failed", self.name)

    def _dispatch(self, data: Any) -> None:
        if not isinstance(data, dict):
            return
        try:
            message = Message.model_validate(data)  # faster than model_construct, and checked
        except ValidationError as exc:
            log.warning("%s: hub sent an invalid message: %s", self.name, exc)
            return
        if message.correlation_id is not None and self._pending.resolve(message):
            return  # a reply goes to its request, not to handlers
        if message.type == "pong" and message.source == "hub":
            return  # heartbeat
        if message.type == "error" and message.source == "hub":
            payload = message.payload or {}
            self.last_error = HubError(str(payload.get("code")), str(payload.get("reason")))
            log.warning("%s: hub refused a message: %s", self.name, self.last_error)
        for route in self._routes.matching(message.type):
            try:
                route.handler(message)
            except Exception:
                log.exception("%s: handler for %r failed", self.name, message.type)
