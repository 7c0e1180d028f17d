"""The hub's second transport: Redis pub/sub between server processes (docs/scaling.md).

Every message published on this process's bus (by an in-process module or a WebSocket client)
is forwarded once to one Redis channel, prefixed with this process's id. Every message on that
channel from another process is published into the local bus, so it reaches local modules and
WebSocket clients through the hub's usual routing (per-client outboxes, back-pressure, coalescing
unchanged), and is not forwarded again. A robot's must-arrive messages (task reports, area, door
and elevator requests) are acknowledged by the leader only, once handled, whichever process the
robot is on (backend/hub/acks.py). Without a broker none of this runs.

Redis pub/sub is at-most-once: while the broker is down, messages between processes are lost
(each process keeps serving its own clients); the bridge reconnects every ``retry_s`` seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
from collections import deque
from typing import Any

import orjson
from redis import asyncio as aioredis
from redis.exceptions import RedisError

from guidebot.messages import Message
from guidebot.service import Service

from .core import Hub

__all__ = ["BROKER_CHANNEL", "BrokerBridge", "process_id"]

log = logging.getLogger(__name__)

BROKER_CHANNEL = "guidebot:bus"
_SEP = b" "


def process_id() -> str:
    """This server process's name across the cluster: host and pid (no space: the separator)."""
    return f"{socket.gethostname()}:{os.getpid()}".replace(" ", "_")


class BrokerBridge(Service):
    """Forward local bus messages to Redis; deliver other processes' messages locally."""

    def __init__(
        self,
        hub: Hub,
        url: str,
        *,
        origin: str | None = None,
        channel: str = BROKER_CHANNEL,
        queue_size: int = 65536,
        retry_s: float = 1.0,
    ) -> None:
        super().__init__()
        self.hub = hub
        self.url = url
        self.origin = origin or process_id()
        self.channel = channel
        self.queue_size = queue_size
        self.retry_s = retry_s
        self.forwarded = 0
        self.received = 0
        self.dropped = 0
        """Messages not forwarded: the outgoing queue was full (broker down or too slow)."""
        self.connected = False
        self._prefix = self.origin.encode() + _SEP
        self._out: deque[bytes] = deque()
        self._wake = asyncio.Event()
        self._incoming: Message | None = None
        """The message being delivered from the broker: not forwarded back (but what local
        modules publish while handling it, such as a grant answering a request, is)."""
        self._endpoint = hub.endpoint(f"broker@{self.origin}")

    async def on_start(self) -> None:
        """Tap every local message; run the sender and the receiver (reconnecting)."""
        self.on_cleanup(self._endpoint.close)
        self.subscribe(self._endpoint, "*", self._forward, tap=True)
        self.hub.forward = self._send
        self.on_cleanup(self._unhook)
        self.spawn(self._send_loop(), name="broker-send")
        self.spawn(self._receive_loop(), name="broker-receive")

    def _unhook(self) -> None:
        self.hub.forward = None

    def stats(self) -> dict[str, Any]:
        return {
            "url": _redact(self.url),
            "process": self.origin,
            "connected": self.connected,
            "forwarded": self.forwarded,
            "received": self.received,
            "dropped": self.dropped,
            "queued": len(self._out),
        }

    # -- outgoing ---------------------------------------------------------------------------
    def _forward(self, message: Message) -> None:
        if message is not self._incoming:  # else it came from the broker: every process has it
            self._send(message)

    def _send(self, message: Message) -> None:
        if len(self._out) >= self.queue_size:
            self.dropped += 1
            return
        self._out.append(self._prefix + self.hub.encode(message))
        self._wake.set()

    async def _send_loop(self) -> None:
        while True:
            client = aioredis.from_url(self.url)
            try:
                while True:
                    await self._wake.wait()
                    self._wake.clear()
                    while self._out:
                        batch = [self._out.popleft() for _ in range(min(512, len(self._out)))]
                        pipe = client.pipeline(transaction=False)
                        for frame in batch:
                            pipe.publish(self.channel, frame)
                        try:
                            await pipe.execute()
                        except (RedisError, OSError):
                            self._out.extendleft(reversed(batch))  # retried after reconnecting
                            raise
                        self.forwarded += len(batch)
            except (RedisError, OSError) as exc:
                log.warning("broker: cannot publish to %s: %s", _redact(self.url), exc)
                self._wake.set()
                await asyncio.sleep(self.retry_s)
            finally:
                await client.aclose()

    # -- incoming ---------------------------------------------------------------------------
    async def _receive_loop(self) -> None:
        while True:
            client = aioredis.from_url(self.url)
            pubsub = client.pubsub()
            try:
                await pubsub.subscribe(self.channel)  # sent; Redis confirms it later
                while True:
                    item = await pubsub.get_message(timeout=None)
                    if item is None:
                        continue
                    if item["type"] == "message":
                        self._deliver(item["data"])
                    elif item["type"] == "subscribe":  # from now on nothing published is missed
                        self.connected = True
                        log.info("broker: %s joined %s", self.origin, _redact(self.url))
            except (RedisError, OSError) as exc:
                log.warning("broker: subscription to %s lost: %s", _redact(self.url), exc)
            finally:
                self.connected = False
                with contextlib.suppress(RedisError, OSError):
                    await pubsub.aclose()
                await client.aclose()
            await asyncio.sleep(self.retry_s)

    def _deliver(self, frame: bytes) -> None:
        origin, _, body = frame.partition(_SEP)
        if origin == self._prefix[:-1]:
            return  # our own message, back from Redis
        try:
            message = Message.model_validate(orjson.loads(body))
        except (orjson.JSONDecodeError, ValueError) as exc:
            log.warning("broker: dropped a malformed frame from %r: %s", origin, exc)
            return
        self.received += 1
        acks = self.hub.acks
        if acks.wanted(message) and message.source:
            # A robot's must-arrive message on another process: the leader handles it once and
            # acknowledges every copy (the ack goes back through the broker); elsewhere it is
            # shown once to local clients (docs/protocol.md, "Delivery guarantee").
            if self.hub.decides():
                if acks.first(message.source, message):
                    self._publish(message)
                self.hub.bus.publish(acks.ack(message))
                return
            if self.hub.starting() or not acks.first_passed(message.source, message):
                return
        self._publish(message)

    def _publish(self, message: Message) -> None:
        self._incoming = message
        try:
            self.hub.bus.publish(message)
        finally:
            self._incoming = None


def _redact(url: str) -> str:
    """The broker URL without its password, for logs and /api/health."""
    scheme, sep, rest = url.partition("://")
    if "@" in rest:
        rest = "***@" + rest.rsplit("@", 1)[1]
    return scheme + sep + rest
