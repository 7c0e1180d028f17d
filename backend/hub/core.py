"""JCentral: the hub that routes messages between in-process modules and WebSocket clients.

In-process modules (Task Manager, Traffic Manager, ...) take ``hub.endpoint(name)``, a plain
``guidebot.bus.Endpoint``. Each WebSocket client is a ``RemoteClient``: a bus endpoint whose
handlers serialise the message (once per message, shared by every subscriber) into the client's
bounded ``Outbox``. A writer task per client drains it (see backend/hub/session.py), so a slow
or dead client only ever fills its own queue.

This module knows nothing about FastAPI: the transport feeds ``Hub.receive`` with raw frames and
drains ``RemoteClient.outbox``.
"""

from __future__ import annotations

import asyncio
import enum
import logging
import operator
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import orjson
from pydantic import BaseModel, ValidationError

from backend.auth import Role
from guidebot.bus import Bus, Endpoint
from guidebot.messages import Message, keep_typed, known_types, payload_model
from guidebot.routing import PatternTable, Route
from guidebot.wire import encode

from . import permissions
from .acks import InboundAcks
from .checks import InboundChecks
from .memory import GcFreezer
from .outbox import Outbox, OutboxOverflow

__all__ = [
    "CLOSE_NAME_IN_USE",
    "CLOSE_OVERFLOW",
    "CLOSE_REPLACED",
    "CLOSE_SHUTDOWN",
    "CLOSE_TOO_MANY_FAILURES",
    "CLOSE_UNAUTHORIZED",
    "COALESCED_TYPES",
    "CONTROL_TYPES",
    "HUB_NAME",
    "ClientRoute",
    "ClientState",
    "ConnectionCallback",
    "Hub",
    "HubBus",
    "RemoteClient",
]

log = logging.getLogger(__name__)

PAGE_ROLES = frozenset(
    {Role.GUI, Role.PANEL, Role.OPERATOR, Role.INSTALLER, Role.AUTHOR, Role.VIEWER}
)
"""Roles whose connections are pages, many at once under one name (``admin#1``, ...)."""

HUB_NAME = "hub"
"""The source of the hub's own messages (welcome, error, pong) and the address of ping."""

# WebSocket close codes (docs/protocol.md).
CLOSE_SHUTDOWN = 1001
CLOSE_REPLACED = 4000
CLOSE_UNAUTHORIZED = 4001
CLOSE_FORBIDDEN = 4003
CLOSE_OVERFLOW = 4008
CLOSE_NAME_IN_USE = 4009
CLOSE_TOO_MANY_FAILURES = 4029

CONTROL_TYPES = frozenset({"subscribe", "unsubscribe", "ping"})
"""Types the hub answers itself instead of publishing (unless addressed to another client)."""

COALESCED_TYPES = frozenset({"robot_state"})
"""Types whose newest message per source replaces the queued one in a slow client's queue."""


ConnectionCallback = Callable[["RemoteClient", bool], None]
"""Called with (client, True) once a client is attached and (client, False) once it is gone."""


STREAMING_S = 0.002
"""Default of ``Hub.streaming_s`` (docs/protocol.md, "Frames")."""


def _always() -> bool:
    return True


def _never() -> bool:
    return False


class ClientState(enum.Enum):
    OPEN = "open"
    CLOSING = "closing"
    CLOSED = "closed"


_TRANSITIONS: dict[ClientState, frozenset[ClientState]] = {
    ClientState.OPEN: frozenset({ClientState.CLOSING, ClientState.CLOSED}),
    ClientState.CLOSING: frozenset({ClientState.CLOSED}),
    ClientState.CLOSED: frozenset(),
}


class HubBus(Bus):
    """The in-process bus plus one rule for remote clients.

    A message addressed to a WebSocket client reaches it even when the client has no matching
    subscription (a robot need not subscribe to receive its task_assigned or a reply).
    """

    def __init__(self) -> None:
        super().__init__()
        self.remote: dict[str, RemoteClient] = {}

    def publish(self, message: Message) -> int:
        delivered = super().publish(message)
        destination = message.destination
        if destination is not None:
            client = self.remote.get(destination)
            if client is not None:
                client.deliver(message)
                delivered += 1
        return delivered


@dataclass(eq=False)
class ClientRoute(Route):
    """One subscription pattern of a WebSocket client, in the hub's pattern table."""

    client: RemoteClient


class RemoteClient:
    """A WebSocket client as the hub sees it: a name, a role, subscriptions, an outbox."""

    def __init__(self, hub: Hub, name: str, role: Role, endpoint: Endpoint) -> None:
        self.hub = hub
        self.name = name
        self.role = role
        self.endpoint = endpoint
        self.outbox = Outbox(hub.queue_size, hub.coalesce_after)
        self.patterns: dict[str, ClientRoute] = {}
        self.state = ClientState.OPEN
        self.close_code: int | None = None
        self.close_reason = ""
        self.received = 0
        self.closing = asyncio.Event()
        """Set once the hub stops routing to this client (its transport should end)."""
        self.frames_sent = 0

    def _move(self, new: ClientState) -> None:
        if new not in _TRANSITIONS[self.state]:
            raise RuntimeError(f"client {self.name}: cannot go from {self.state} to {new}")
        self.state = new

    def deliver(self, message: Message) -> None:
        """Queue a message addressed to this client; overflow closes this client only."""
        if self.state is not ClientState.OPEN:
            return
        key = message.source if message.type in COALESCED_TYPES else None
        try:
            self.outbox.put(self.hub.encode(message), key)
        except OutboxOverflow as exc:
            self.hub.overflow_disconnects += 1
            self.request_close(CLOSE_OVERFLOW, f"slow consumer: {exc}")

    def send_direct(self, message: Message) -> None:
        """A message from the hub itself (welcome, error, pong), not routed through the bus."""
        if self.state is not ClientState.OPEN:
            return
        try:
            self.outbox.put(encode(message))
        except OutboxOverflow as exc:
            self.hub.overflow_disconnects += 1
            self.request_close(CLOSE_OVERFLOW, f"slow consumer: {exc}")

    def error(self, code: str, reason: str, message_id: str | None = None) -> None:
        self.hub.refused += 1
        self.send_direct(
            Message(
                type="error",
                source=HUB_NAME,
                destination=self.name,
                correlation_id=message_id,
                payload={"code": code, "reason": reason, "message_id": message_id},
            )
        )

    def subscribe(self, pattern: str) -> None:
        if pattern not in self.patterns:
            route = self.patterns[pattern] = ClientRoute(pattern, self.deliver, self)
            self.hub.subscriptions.add(route)

    def unsubscribe(self, pattern: str) -> None:
        route = self.patterns.pop(pattern, None)
        if route is not None:
            self.hub.subscriptions.remove(route)

    def request_close(self, code: int, reason: str) -> None:
        """Stop routing to this client; its transport closes the socket with code and reason."""
        if self.state is not ClientState.OPEN:
            return
        self._move(ClientState.CLOSING)
        self.closing.set()
        self.close_code, self.close_reason = code, reason
        log.warning("hub: closing %s (%d): %s", self.name, code, reason)
        self.hub.detach(self)
        self.outbox.close()

    def stats(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "role": self.role.value,
            "state": self.state.value,
            "patterns": sorted(self.patterns),
            "queued": len(self.outbox),
            "superseded": self.outbox.superseded,
            "received": self.received,
            "frames_sent": self.frames_sent,
        }


class Hub:
    """JCentral: one bus for in-process modules and WebSocket clients (docs/protocol.md)."""

    def __init__(
        self,
        *,
        queue_size: int = 4096,
        coalesce_after: int = 256,
        batch_max: int = 512,
        linger: float = 0.0,
        max_message_bytes: int = 1 << 20,
        gc_freeze: bool = True,
    ) -> None:
        self.bus = HubBus()
        self.memory = GcFreezer(enabled=gc_freeze)
        self.queue_size = queue_size
        self.coalesce_after = coalesce_after
        self.batch_max = batch_max
        self.linger = linger
        self.streaming_s = STREAMING_S
        """A client sent a frame less than this long ago is streaming: its writer lets the event
        loop turn once more before it takes its batch (backend/hub/session.py)."""
        self.max_message_bytes = max_message_bytes
        self.large_frames = asyncio.Lock()
        """Taken for one loop turn by a writer before it sends one message of
        ``LARGE_FRAME_BYTES`` or more (backend/hub/session.py): one per turn of the loop."""
        self.refused = 0
        self.overflow_disconnects = 0
        self.checks = InboundChecks()
        """What a client's message must pass besides being well formed (backend/hub/checks.py):
        the hub's publish permissions, and what the server's parts register (the task_request
        rate limit: backend/tasks/inbound.py)."""
        permissions.install(self.checks)
        self.forwards_unknown = False
        """With a broker (backend/hub/broker.py) a destination may live on another process."""
        self.acks = InboundAcks(source=HUB_NAME)
        """Must-arrive messages from clients: acknowledged once handled, repeats dropped."""
        self.decides: Callable[[], bool] = _always
        """Whether the modules that handle must-arrive messages run here and may decide: always
        with one process; with a broker, on the serving leader within its lease (cluster.py).
        Elsewhere nothing is acknowledged: the leader does it (backend/hub/broker.py)."""
        self.starting: Callable[[], bool] = _never
        """With a broker: this process has won the leadership and its deciding modules are
        starting (cluster.py). Those already up would handle a must-arrive message while
        nothing may acknowledge it yet, and handle again the copy the sender sends for want of
        an ack: such a message is not published until they all serve."""
        self.forward: Callable[[Message], None] | None = None
        """With a broker: hand a message to the other processes only (a copy sent again, which
        this process's clients already have)."""
        self._on_connection: list[ConnectionCallback] = []
        self._known: frozenset[str] = frozenset()
        self._models: dict[str, type[BaseModel]] = {}
        self._encoded_message: Message | None = None
        self._encoded = b""
        self._gui_counter = 0
        self.subscriptions: PatternTable[ClientRoute] = PatternTable(
            distinct=operator.attrgetter("client")
        )
        """WebSocket subscriptions: one bus subscription ("*") finds every remote recipient of
        a message once, however many of its patterns match (the table keeps one route per
        client, worked out once per type), and queues the message serialised once."""
        self._own = self.bus.endpoint(HUB_NAME)
        self._own.subscribe("*", self._fan_out)

    # -- in-process side --------------------------------------------------------------------
    def endpoint(self, name: str) -> Endpoint:
        """A named in-process client (Task Manager, ...): publish, subscribe, request, reply."""
        if name == HUB_NAME or name in self.bus.remote:
            raise ValueError(f"the name {name!r} is taken")
        return self.bus.endpoint(name)

    @property
    def clients(self) -> dict[str, RemoteClient]:
        return self.bus.remote

    def on_connection(self, callback: ConnectionCallback) -> Callable[[], None]:
        """Be told when a WebSocket client is attached or gone; returns the unsubscribe."""
        self._on_connection.append(callback)
        return lambda: self._on_connection.remove(callback)

    def _connection_changed(self, client: RemoteClient, connected: bool) -> None:
        for callback in list(self._on_connection):
            try:
                callback(client, connected)
            except Exception:
                log.exception("hub: connection callback failed for %s", client.name)

    def encode(self, message: Message) -> bytes:
        """JSON bytes of a message, computed once however many clients receive it."""
        if message is not self._encoded_message:
            self._encoded = encode(message)
            self._encoded_message = message
        return self._encoded

    def recipients(self, message_type: str) -> int:
        """How many WebSocket clients a published (not addressed) message of this type reaches."""
        return len(self.subscriptions.matching(message_type))

    def _fan_out(self, message: Message) -> None:
        """Queue a published message for every WebSocket client subscribed to its type."""
        if message.destination is not None:
            return  # addressed messages reach their client through HubBus.publish
        routes = self.subscriptions.matching(message.type)
        if not routes:
            return
        data = self.encode(message)
        key = message.source if message.type in COALESCED_TYPES else None
        for route in routes:
            client = route.client
            if client.state is not ClientState.OPEN:
                continue
            try:
                client.outbox.put(data, key)
            except OutboxOverflow as exc:
                self.overflow_disconnects += 1
                client.request_close(CLOSE_OVERFLOW, f"slow consumer: {exc}")

    # -- remote clients ---------------------------------------------------------------------
    def resolve_name(self, principal_name: str, role: Role, requested: str | None) -> str:
        """The hub name of a new connection; raises PermissionError for a name not allowed.

        Robots are their token's name, and so are modules and admins that pick one with
        ``?name=``: a reconnection takes the name back. A person's pages (GUI, panel, operator
        tokens, and an admin token that asks for no name) are many at once: a console in a
        second tab gets a name of its own (``admin#1``, ``admin#2``, ...) instead of closing
        the first.
        """
        if requested and requested != principal_name and role not in (Role.ADMIN, Role.MODULE):
            raise PermissionError(
                f"a {role.value} token may only connect as {principal_name!r}, not {requested!r}"
            )
        name = requested or principal_name
        pages = role in PAGE_ROLES or (role is Role.ADMIN and not requested)
        if pages and self._taken(name):
            base = name
            while self._taken(name):
                self._gui_counter += 1
                name = f"{base}#{self._gui_counter}"
        return name

    def _taken(self, name: str) -> bool:
        return name == HUB_NAME or self.bus.get_endpoint(name) is not None

    def attach(self, name: str, role: Role) -> RemoteClient:
        """Register a remote client. A reconnecting client replaces its stale connection."""
        if name == HUB_NAME:
            raise PermissionError(f"{HUB_NAME!r} is reserved")
        old = self.bus.remote.get(name)
        if old is not None:
            old.request_close(CLOSE_REPLACED, "replaced by a newer connection with this name")
        elif self.bus.get_endpoint(name) is not None:
            raise PermissionError(f"the name {name!r} belongs to an in-process module")
        client = RemoteClient(self, name, role, self.bus.endpoint(name))
        self.bus.remote[name] = client
        self.memory.attached(len(self.bus.remote))
        client.send_direct(
            Message(
                type="welcome",
                source=HUB_NAME,
                destination=name,
                payload={"name": name, "role": role.value},
            )
        )
        self._connection_changed(client, True)
        return client

    def detach(self, client: RemoteClient) -> None:
        """Forget a client: no more routing to it. Safe to call twice."""
        gone = self.bus.remote.get(client.name) is client
        if gone:
            del self.bus.remote[client.name]
            client.endpoint.close()
            self.memory.detached(len(self.bus.remote))
        client.closing.set()
        for route in client.patterns.values():
            self.subscriptions.remove(route)
        client.patterns.clear()
        if client.state is not ClientState.CLOSED:
            client._move(ClientState.CLOSED)
            client.outbox.close()
        if gone:
            self._connection_changed(client, False)

    def close(self) -> None:
        """Server shutdown: every client is told why."""
        self.memory.stop()
        for client in list(self.bus.remote.values()):
            client.request_close(CLOSE_SHUTDOWN, "server shutting down")

    # -- inbound ----------------------------------------------------------------------------
    def receive(self, client: RemoteClient, raw: str | bytes) -> None:
        """Handle one frame from a client: a message object or a JSON array of them."""
        if client.state is not ClientState.OPEN:
            return
        if len(raw) > self.max_message_bytes:
            client.error("too_large", f"frame larger than {self.max_message_bytes} bytes")
            return
        try:
            data = orjson.loads(raw)
        except orjson.JSONDecodeError as exc:
            client.error("malformed_json", f"frame is not JSON: {exc}")
            return
        if isinstance(data, list):
            for item in data:
                self._receive_one(client, item)
        else:
            self._receive_one(client, data)

    def _receive_one(self, client: RemoteClient, data: Any) -> None:
        client.received += 1
        if not isinstance(data, dict):
            client.error("malformed_message", "a message is a JSON object")
            return
        raw_id = data.get("id")
        message_id = raw_id if isinstance(raw_id, str) else None
        type_ = data.get("type")
        if not isinstance(type_, str):
            client.error("invalid_envelope", "a message needs a string 'type'", message_id)
            return
        if type_ not in self._known:
            self._known = known_types()  # modules may register types after we started
            if type_ not in self._known:
                client.error("unknown_type", f"unknown message type {type_!r}", message_id)
                return
        plan = self.checks.plans.get(type_) or self.checks.plan(type_)
        on_type, on_envelope, on_payload, on_routed = plan
        for check in on_type:
            if (refusal := check(client, type_, None)) is not None:
                client.error(*refusal, message_id)
                return
        try:
            message = Message.model_validate(data)
        except ValidationError as exc:
            client.error("invalid_envelope", _short(exc), message_id)
            return
        for check in on_envelope:
            if (refusal := check(client, type_, message)) is not None:
                client.error(*refusal, message.id)
                return
        model = self._models.get(type_)
        if model is None:
            model = self._models[type_] = payload_model(type_)
        try:
            payload = model.model_validate(message.payload)
        except ValidationError as exc:
            client.error("invalid_payload", _short(exc, "payload"), message.id)
            return
        keep_typed(message, payload)  # typed once, here: handlers on(model) get this object
        for check in on_payload:
            if (refusal := check(client, type_, message)) is not None:
                client.error(*refusal, message.id)
                return
        message.source = client.name
        if type_ in CONTROL_TYPES and message.destination in (None, HUB_NAME):
            self._control(client, message)
            return
        destination = message.destination
        if destination is not None and (
            destination == HUB_NAME
            or (self.bus.get_endpoint(destination) is None and not self.forwards_unknown)
        ):
            client.error("unknown_destination", f"no client named {destination!r}", message.id)
            return
        for check in on_routed:
            if (refusal := check(client, type_, message)) is not None:
                client.error(*refusal, message.id)
                return
        if not self.acks.wanted(message):
            self.bus.publish(message)
            return
        if not self.decides():
            if self.starting():
                return  # sent again for want of an ack, handled once they all serve
            # The leader handles and acknowledges it; every copy goes on (the first may have
            # found no leader), this process's clients see the first.
            if self.acks.first_passed(client.name, message):
                self.bus.publish(message)
            elif self.forward is not None:
                self.forward(message)
            return
        if self.acks.first(client.name, message):
            self.bus.publish(message)  # handlers run inline: handled once this returns
        client.send_direct(self.acks.ack(message))

    def _control(self, client: RemoteClient, message: Message) -> None:
        if message.type == "ping":
            client.send_direct(message.reply("pong", {}, source=HUB_NAME))
            return
        patterns: list[str] = message.payload["patterns"]  # validated (Subscribe)
        if not all(0 < len(p) <= 64 for p in patterns):
            client.error(
                "invalid_payload",
                "payload.patterns: each pattern is 1-64 characters",
                message.id,
            )
            return
        for pattern in patterns:
            if message.type == "subscribe":
                client.subscribe(pattern)
            else:
                client.unsubscribe(pattern)


def _short(exc: ValidationError, within: str = "") -> str:
    """The first three mistakes, each by its place (``payload.priority: Input should be a
    valid integer (got a boolean)``): the sender learns which field to fix."""
    parts = []
    for err in exc.errors()[:3]:
        where = ".".join(str(p) for p in (within, *err["loc"]) if p != "") or "message"
        given = "" if err["type"] in ("missing", "extra_forbidden") else _kind(err["input"])
        parts.append(f"{where}: {err['msg']}{given}")
    return "; ".join(parts)


_JSON_KINDS = {
    bool: "a boolean",
    int: "an integer",
    float: "a number",
    str: "a string",
    list: "an array",
    dict: "an object",
    type(None): "null",
}


def _kind(value: Any) -> str:
    kind = _JSON_KINDS.get(type(value))
    return f" (got {kind})" if kind is not None else ""
