"""One MQTT session that stays up: connect, subscribe, hand each message on, and reconnect with
back-off when the broker goes; used by the master control and the simulated vehicle alike."""

from __future__ import annotations

import asyncio
import json
import logging
import random
import socket
import ssl
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import aiomqtt

from guidebot.service import Service
from guidebot.vda5050.topics import BrokerAddress

__all__ = ["BrokerUnreachable", "LastWill", "MqttSession"]

log = logging.getLogger(__name__)

Handler = Callable[[str, bytes], None]

NO_DELAY = ((socket.IPPROTO_TCP, socket.TCP_NODELAY, 1),)
"""Each message leaves at once: paho leaves Nagle's algorithm on, which held a small state or
order back for tens of milliseconds behind the previous one's acknowledgement."""


class BrokerUnreachable(ConnectionError):
    """The first connection to the broker failed (the message names the broker)."""


@dataclass(frozen=True)
class LastWill:
    topic: str
    payload: dict[str, Any]
    retain: bool = True


class MqttSession(Service):
    """Keeps one connection to ``broker``: ``on_message(topic, payload)`` for every message of
    ``subscriptions``, ``on_connect()`` after each (re)connection, ``on_error(reason)`` after
    each failed or lost one, ``publish`` while connected.

    ``start`` waits for the first connection up to ``first_timeout_s`` and raises
    BrokerUnreachable naming the broker when ``require`` is set; otherwise it keeps trying in
    the background, 0.5 s doubling to ``max_backoff_s`` (±20 %), and logs each failure once."""

    def __init__(
        self,
        broker: BrokerAddress,
        *,
        client_id: str,
        subscriptions: list[str],
        on_message: Handler,
        on_connect: Callable[[], None] | None = None,
        on_error: Callable[[str], None] | None = None,
        will: LastWill | None = None,
        cafile: str | None = None,
        first_timeout_s: float = 5.0,
        require: bool = False,
        max_backoff_s: float = 10.0,
    ) -> None:
        super().__init__()
        self.broker = broker
        self.client_id = client_id
        self.subscriptions = subscriptions
        self.on_message = on_message
        self.on_connect = on_connect
        self.on_error = on_error
        self.will = will
        self.cafile = cafile
        self.first_timeout_s = first_timeout_s
        self.require = require
        self.max_backoff_s = max_backoff_s
        self.connected = asyncio.Event()
        self.connections = 0
        self.last_error: str | None = None
        self._client: aiomqtt.Client | None = None

    def _make_client(self) -> aiomqtt.Client:
        tls: ssl.SSLContext | None = None
        if self.broker.tls:
            tls = ssl.create_default_context(cafile=self.cafile)
        will = None
        if self.will is not None:
            will = aiomqtt.Will(
                self.will.topic, json.dumps(self.will.payload), qos=1, retain=self.will.retain
            )
        return aiomqtt.Client(
            self.broker.host,
            self.broker.port,
            username=self.broker.username,
            password=self.broker.password,
            identifier=self.client_id,
            will=will,
            tls_context=tls,
            timeout=self.first_timeout_s,
            keepalive=10,
            socket_options=NO_DELAY,
        )

    async def on_start(self) -> None:
        first: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.spawn(self._run(first), f"mqtt {self.client_id}")
        if not self.require:
            return
        try:
            await asyncio.wait_for(asyncio.shield(first), self.first_timeout_s + 1)
        except (TimeoutError, OSError, aiomqtt.MqttError) as exc:
            reason = self.last_error or str(exc) or type(exc).__name__
            raise BrokerUnreachable(
                f"cannot reach the MQTT broker {self.broker}: {reason}"
            ) from None

    async def _run(self, first: asyncio.Future[None]) -> None:
        delay = 0.5
        while True:
            try:
                async with self._make_client() as client:
                    self._client = client
                    for pattern in self.subscriptions:
                        await client.subscribe(pattern, qos=1)
                    self.connections += 1
                    self.connected.set()
                    if self.connections > 1:
                        log.info("%s: MQTT broker %s back", self.client_id, self.broker)
                    self.last_error = None
                    delay = 0.5
                    if not first.done():
                        first.set_result(None)
                    if self.on_connect is not None:
                        self.on_connect()
                    async for message in client.messages:
                        payload = message.payload
                        data = payload if isinstance(payload, bytes) else str(payload).encode()
                        try:
                            self.on_message(message.topic.value, data)
                        except Exception:
                            log.exception("%s: handling %s failed", self.client_id, message.topic)
            except aiomqtt.MqttError as exc:
                reason = str(exc) or type(exc).__name__
                if self.last_error is None:
                    log.warning(
                        "%s: MQTT broker %s: %s (reconnecting with back-off)",
                        self.client_id,
                        self.broker,
                        reason,
                    )
                self.last_error = reason
                if self.on_error is not None:
                    self.on_error(reason)
            finally:
                self._client = None
                self.connected.clear()
            if not first.done() and self.require:
                first.set_exception(BrokerUnreachable(self.last_error or "no answer"))
                first.exception()  # retrieved: the starter reads last_error
            await asyncio.sleep(delay * random.uniform(0.8, 1.2))
            delay = min(delay * 2, self.max_backoff_s)

    async def publish(self, topic: str, message: dict[str, Any], *, retain: bool = False) -> bool:
        """Send ``message`` as JSON (QoS 1); False when the broker is not connected now."""
        client = self._client
        if client is None:
            return False
        try:
            await client.publish(topic, json.dumps(message), qos=1, retain=retain)
        except aiomqtt.MqttError as exc:
            log.warning("%s: publish to %s failed: %s", self.client_id, topic, exc)
            return False
        return True
