"""Acknowledged delivery of the messages that must arrive (docs/protocol.md, "Delivery
guarantee").

TCP gives no receipt: a message written just before a link drops may die in flight. The
senders of must-arrive messages keep each one until its receiver answers ``ack`` (payload
``message_id`` = the message's id) and send it again with back-off until
then, or until the receiver is known gone; the receivers acknowledge every copy and handle one
id once. At least once plus idempotent receivers is effectively once, while both ends live.

- ``Courier``: the sender's side (the Task Manager, the Traffic Manager, the robot's link);
- ``Seen``: the receiver's side, a bounded memory of the ids already handled.
"""

from __future__ import annotations

import asyncio
import logging
import random
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field

from guidebot.bus import BusEndpoint
from guidebot.messages import Message

__all__ = [
    "ACK",
    "ANSWERED",
    "MUST_ARRIVE_DOWN",
    "MUST_ARRIVE_UP",
    "Courier",
    "Seen",
    "ack_for",
    "courier_for",
    "listen",
]

log = logging.getLogger(__name__)

ACK = "ack"

MUST_ARRIVE_DOWN = frozenset({"task_assigned", "task_cancel", "area_granted", "evacuate"})
"""Server -> robot: sent by a Courier, acknowledged by the robot's link."""

MUST_ARRIVE_UP = frozenset(
    {
        # reports the Task Manager acts on
        "task_started",
        "task_ended",
        "task_request",
        "battery_low",
        "battery_panic",
        "robot_fault",
        "petri_net_ended",
        # requests and releases: areas, doors, elevators
        "request_area",
        "release_area",
        "open_door",
        "close_door",
        "release_door",
        "call_elevator",
        # where the robot is: the fleet's invariants are checked on it (a node_reached lost
        # as the server died left a robot in the lift cabin for the soak's checker)
        "node_reached",
    }
)
"""Robot -> server: sent by the link's Courier, acknowledged by the hub once the server's
in-process modules have handled it (backend/hub/acks.py), except the ``ANSWERED`` ones."""

ANSWERED = frozenset({"task_request"})
"""Must-arrive requests acknowledged by the module that answers them, not by the hub: the Task
Manager answers and acknowledges a task_request once the task is written, and answers a
repeated id with the same task."""


def ack_for(message: Message, source: str) -> Message:
    """The acknowledgement of ``message``, from ``source`` back to its sender."""
    return Message(
        type=ACK,
        source=source,
        destination=message.source or None,
        payload={"message_id": message.id},
    )  # no correlation_id: an ack must never complete a request() waiting for the real reply


class Seen:
    """The ids a receiver has handled, oldest forgotten first (bounded memory)."""

    def __init__(self, size: int = 4096) -> None:
        self.size = size
        self._ids: OrderedDict[Hashable, None] = OrderedDict()
        self.duplicates = 0

    def __contains__(self, key: object) -> bool:
        return key in self._ids

    def first(self, key: Hashable) -> bool:
        """True the first time ``key`` is seen (handle it), False for a repeat (ack only)."""
        if key in self._ids:
            self._ids.move_to_end(key)
            self.duplicates += 1
            return False
        self._ids[key] = None
        if len(self._ids) > self.size:
            self._ids.popitem(last=False)
        return True


@dataclass(eq=False)
class _Pending:
    message: Message
    acker: str
    key: Hashable | None
    delay: float
    sent: int = 1
    online: bool = True
    """Sent while the link was up (False: it waits in an offline queue that will flush it)."""
    timer: asyncio.TimerHandle | None = field(default=None, repr=False)


class Courier:
    """Sends must-arrive messages and sends each again with back-off until it is acknowledged.

    ``send`` puts a message on the wire. A message's acknowledgement must come from its
    destination (or from ``default_acker`` when it has none, e.g. ``hub``): an ack from anyone
    else is ignored, so no client can silence another's retries. Retries back off from
    ``initial_s`` doubling to ``max_s`` (±20 % jitter); ``forget(destination)`` drops the
    messages of a receiver known gone; ``withdraw(key)`` drops one the sender no longer wants
    delivered (a task taken back). At most ``max_pending`` wait; beyond, the oldest is dropped
    and logged. Without a running event loop nothing is retried (synchronous unit tests).
    """

    def __init__(
        self,
        send: Callable[[Message], None],
        *,
        name: str,
        default_acker: str = "",
        initial_s: float = 1.0,
        max_s: float = 8.0,
        max_pending: int = 1000,
        reliable: Callable[[str | None], bool] | None = None,
    ) -> None:
        self._send = send
        self.name = name
        self.default_acker = default_acker
        self.initial_s = initial_s
        self.max_s = max_s
        self.max_pending = max_pending
        self.reliable = reliable
        """Destinations that cannot lose a message (an in-process endpoint): sent, not kept."""
        self._pending: OrderedDict[str, _Pending] = OrderedDict()
        self._keyed: dict[Hashable, str] = {}
        """key -> id of the message kept under it: replacing and withdrawing are O(1)."""
        self.paused = False
        self.sent = 0
        self.retries = 0
        self.acked = 0
        self.dropped = 0

    @property
    def pending(self) -> int:
        return len(self._pending)

    def pending_ids(self) -> list[str]:
        return list(self._pending)

    def post(self, message: Message, *, key: Hashable | None = None) -> Message:
        """Send ``message`` now and keep it until its acknowledgement comes."""
        self.sent += 1
        self._send(message)
        if self.reliable is not None and self.reliable(message.destination):
            return message
        if key is not None:
            self.withdraw(key)  # a newer message for the same thing replaces the older one
        entry = _Pending(
            message,
            "" if message.type in ANSWERED else message.destination or self.default_acker,
            key,
            self.initial_s,
            online=not self.paused,
        )
        self._pending[message.id] = entry
        if key is not None:
            self._keyed[key] = message.id
        if len(self._pending) > self.max_pending:
            oldest = next(iter(self._pending.values()))
            self._drop(oldest.message.id)
            self.dropped += 1
            log.warning(
                "%s: %d unacknowledged messages; dropped the oldest (%s %s)",
                self.name,
                self.max_pending,
                oldest.message.type,
                oldest.message.id,
            )
        self._schedule(entry)
        return message

    def on_ack(self, ack: Message) -> bool:
        """An ``ack`` arrived: stop sending the message it names. True if it was pending."""
        # An ack names the message in its payload; a refusal (error) in its correlation id.
        message_id = str((ack.payload or {}).get("message_id") or ack.correlation_id or "")
        entry = self._pending.get(message_id)
        if entry is None:
            return False
        if entry.acker and ack.source != entry.acker:
            log.warning(
                "%s: ack of %s from %s ignored (expected from %s)",
                self.name,
                message_id,
                ack.source,
                entry.acker,
            )
            return False
        self._drop(message_id)
        self.acked += 1
        return True

    def forget(self, destination: str) -> int:
        """The receiver is gone: stop sending it anything. Returns how many were dropped."""
        gone = [i for i, e in self._pending.items() if e.message.destination == destination]
        for message_id in gone:
            self._drop(message_id)
        if gone:
            log.info(
                "%s: %s is gone; %d unacknowledged message(s) no longer sent",
                self.name,
                destination,
                len(gone),
            )
        return len(gone)

    def withdraw(self, key: Hashable) -> None:
        """Stop sending the message kept under ``key`` (its content is no longer true)."""
        message_id = self._keyed.get(key)
        if message_id is not None:
            self._drop(message_id)

    def pause(self) -> None:
        """The link is down: no retries (they would only fill the offline queue)."""
        self.paused = True
        for entry in self._pending.values():
            self._cancel(entry)

    def resume(self) -> None:
        """The link is back: what was sent before the drop and never acknowledged may have
        died in flight and goes again now; what waited in the offline queue has just been
        flushed and gets the usual time to be acknowledged."""
        self.paused = False
        for entry in list(self._pending.values()):
            if entry.online:
                self._resend(entry)
            else:
                entry.online = True
                entry.delay = self.initial_s
                self._schedule(entry)

    def close(self) -> None:
        """Stop every retry (the sender stops)."""
        for entry in self._pending.values():
            self._cancel(entry)
        self._pending.clear()
        self._keyed.clear()

    def _drop(self, message_id: str) -> None:
        """Forget one kept message: its retry timer and its key."""
        entry = self._pending.pop(message_id, None)
        if entry is None:
            return
        if entry.key is not None and self._keyed.get(entry.key) == message_id:
            del self._keyed[entry.key]
        self._cancel(entry)

    # -- retries ----------------------------------------------------------------------------
    def _schedule(self, entry: _Pending) -> None:
        if self.paused:
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return
        delay = entry.delay * random.uniform(0.8, 1.2)
        entry.timer = loop.call_later(delay, self._due, entry.message.id)

    def _due(self, message_id: str) -> None:
        entry = self._pending.get(message_id)
        if entry is None or self.paused:
            return
        entry.timer = None
        self._resend(entry)

    def _resend(self, entry: _Pending) -> None:
        self._cancel(entry)
        entry.sent += 1
        entry.delay = min(self.max_s, entry.delay * 2)
        self.retries += 1
        if entry.sent in (2, 5) or entry.sent % 20 == 0:
            log.info(
                "%s: %s %s to %s not acknowledged, sent again (copy %d)",
                self.name,
                entry.message.type,
                entry.message.id,
                entry.acker or "the server",
                entry.sent,
            )
        self._send(entry.message)
        self._schedule(entry)

    @staticmethod
    def _cancel(entry: _Pending) -> None:
        if entry.timer is not None:
            entry.timer.cancel()
            entry.timer = None


def _in_process(endpoint: BusEndpoint) -> Callable[[str | None], bool] | None:
    """Destinations an in-process bus delivers synchronously (nothing to lose on the way):
    endpoints of the same bus that are not WebSocket clients."""
    bus = getattr(endpoint, "bus", None)
    get_endpoint = getattr(bus, "get_endpoint", None)
    if get_endpoint is None:
        return None
    remote: dict[str, object] = getattr(bus, "remote", {})

    def reliable(destination: str | None) -> bool:
        return (
            destination is not None
            and destination not in remote
            and get_endpoint(destination) is not None
        )

    return reliable


def courier_for(endpoint: BusEndpoint, *, initial_s: float = 1.0, max_s: float = 8.0) -> Courier:
    """A Courier for a server module's endpoint (``listen`` feeds it once the module starts)."""
    return Courier(
        endpoint.send,
        name=endpoint.name,
        reliable=_in_process(endpoint),
        initial_s=initial_s,
        max_s=max_s,
    )


def listen(endpoint: BusEndpoint, courier: Courier) -> list[Callable[[], None]]:
    """Give ``courier`` the acks addressed to ``endpoint``, and make it forget a robot on
    ``robot_disconnected`` (the hub's connection event). Returns the unsubscribe functions."""

    def on_ack(message: Message) -> None:
        if message.destination == endpoint.name:
            courier.on_ack(message)

    def on_gone(message: Message) -> None:
        robot = message.payload.get("robot") or message.payload.get("name")
        if isinstance(robot, str):
            courier.forget(robot)

    return [endpoint.subscribe(ACK, on_ack), endpoint.subscribe("robot_disconnected", on_gone)]
