"""The link (the paper's robot Wi-Fi interface): a gateway between the on-board bus and the hub.

Up: the on-board messages the server must see (state, alarms, faults, task reports, requests to
the Traffic Manager and the building) are sent to the hub. Down: messages from the hub for this
robot (tasks, path replies, area grants) and the building's broadcasts the robot needs (doors,
elevators) are published on the on-board bus; a reply goes back to the on-board module that sent
the request (its correlation id is remembered), so ``endpoint.request`` works across the link.

While the link is down the robot goes on by itself; what it must report waits in the hub
client's bounded queue (overflow: robot_state is coalesced to the latest, otherwise the oldest
message is dropped and counted) and is flushed in order on reconnect, after which the agent
resynchronises (``on_connect``: robot_state with the running task at once).

Delivery (guidebot/delivery.py, docs/protocol.md "Delivery guarantee"): the must-arrive
reports and requests going up are kept by a Courier until acknowledged and sent again with
back-off (paused while the link is down; on reconnect those sent before the drop go again at
once). The must-arrive messages coming down (task_assigned, task_cancel, area_granted) are
acknowledged to their sender, every copy, and a repeated id is not published on board again.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from typing import Any, Protocol

from pydantic import BaseModel, ValidationError

from guidebot.bus import Endpoint, Handler
from guidebot.delivery import ACK, MUST_ARRIVE_DOWN, MUST_ARRIVE_UP, Courier, Seen, ack_for
from guidebot.messages import Message, UnknownMessageType, payload_model
from guidebot.payloads.robot import RobocanStatus
from guidebot.service import Service

__all__ = ["DOWN_TYPES", "ROBOCAN_EVERY_S", "UP_TYPES", "Link", "StatusThrottle", "Upstream"]

log = logging.getLogger(__name__)

UP_TYPES: tuple[str, ...] = (
    "robot_state",
    "battery_low",
    "battery_panic",
    "robot_fault",
    "task_started",
    "task_ended",
    "task_reaction",
    "task_request",
    "tour_progress",
    "get_path",
    "request_area",
    "release_area",
    "open_door",
    "release_door",
    "call_elevator",
    "node_reached",
    "petri_net_ended",
    "site_loaded",
    "nets_loaded",
    "petri_net_event",
    "robocan_status",
    "evacuation_state",
    "speech_started",
    "speech_ended",
)
"""On-board message types sent to the hub (petri_net_event: the console's RoboGraph monitor;
robocan_status: its robot view's CAN modules and counters; speech_started/ended: the visitor's
phone captions what its robot says)."""

LIVE_ONLY = frozenset({"petri_net_event", "robocan_status", "speech_started", "speech_ended"})
"""Up types sent only while the link is up (never queued offline): the console's monitor
follows live markings and CAN counters; queued, they would push reports out of the bounded
offline queue (a stale status is worth nothing: the next one is a second away)."""

ROBOCAN_EVERY_S = 5.0
"""robocan_status goes up at most this often (on board it comes every second: its counters
change with every frame), and at once when a module changes state or the link comes back."""

DOWN_TYPES: tuple[str, ...] = (
    "task_assigned",
    "task_cancel",
    "path",
    "area_granted",
    "area_yield",
    "door_opened",
    "door_closed",
    "elevator_in_position",
    "command_failed",
    "site_changed",
    "nets_changed",
    "error",
    "kill_petri_net",
    "petri_net_debug",
    "evacuate",
    "emergency_changed",
    "closures_changed",
    "next_tours",
    "visitor_service",
)
"""Hub message types published on the on-board bus (addressed to the robot, or broadcast)."""

ADDRESSED_ONLY = frozenset({"kill_petri_net", "petri_net_debug"})
"""Down types taken only when addressed to this robot (staff kill or debug one robot's net)."""

MAX_PENDING_REPLIES = 1000

SEEN_IDS = 1024
"""Must-arrive ids remembered for de-duplication (a repeat comes within seconds)."""


def _typed_at_the_edge(message: Message) -> BaseModel | None:
    """A message from the server, as its payload model: validated once, here, so that the
    on-board handlers subscribed by model get it without validating again. One that is not its
    model still goes on board as JSON (its typed handlers never see it: guidebot/bus.py)."""
    try:
        return message.typed(payload_model(message.type))
    except UnknownMessageType:
        return None
    except ValidationError as exc:
        log.warning("%r from the hub is not its model: %s", message.type, exc.errors()[:3])
        return None


class StatusThrottle:
    """Lets ``robocan_status`` through at most every ``every_s``, but at once when a module's
    state changed (a module lost is news; a frame counter is not)."""

    def __init__(self, every_s: float) -> None:
        self.every_s = every_s
        self.last_sent = -math.inf
        self.last_states: tuple[tuple[str, int, str], ...] | None = None
        self.held = 0
        """Statuses not sent (the next one carries newer counters)."""

    def allow(self, message: Message, now: float) -> bool:
        try:
            states = message.typed(RobocanStatus).module_states()
        except ValidationError as exc:
            log.warning("robocan_status not sent: %s", exc.errors()[0]["msg"])
            return False
        if states == self.last_states and now - self.last_sent < self.every_s:
            self.held += 1
            return False
        self.last_states, self.last_sent = states, now
        return True

    def reset(self) -> None:
        """The link is back: the next status goes at once."""
        self.last_states = None


class Upstream(Protocol):
    """What the link needs from the hub client (guidebot.client.HubClient has it)."""

    name: str
    connected: asyncio.Event

    def send(self, message: Message) -> None: ...

    def subscribe(self, pattern: str, handler: Handler) -> Callable[[], None]: ...

    def on_connect(self, callback: Callable[[], Awaitable[None] | None]) -> Callable[[], None]: ...

    # Optional (HubClient has it): ``on_disconnect(callback) -> unsubscribe``, called when an
    # established connection is lost. Without it the link polls ``connected`` at 10 Hz.


class Link(Service):
    """Forwards messages both ways between ``onboard`` and ``upstream``."""

    def __init__(
        self,
        onboard: Endpoint,
        upstream: Upstream,
        robot: str,
        *,
        on_connect: Callable[[], Any] | None = None,
        on_disconnect: Callable[[], Any] | None = None,
        retry_initial_s: float = 1.0,
        retry_max_s: float = 8.0,
        robocan_every_s: float = ROBOCAN_EVERY_S,
    ) -> None:
        super().__init__()
        self.onboard = onboard
        self.upstream = upstream
        self.robot = robot
        self.on_connect_callback = on_connect
        self.on_disconnect_callback = on_disconnect
        self.sent_up = 0
        self.sent_down = 0
        self.connections = 0
        self.on_message_down: Callable[[Message], None] | None = None
        # Request id -> on-board endpoint that sent it (bounded: oldest forgotten first).
        self._requesters: OrderedDict[str, str] = OrderedDict()
        self.courier = Courier(
            upstream.send,
            name=f"{robot} link",
            default_acker="hub",
            initial_s=retry_initial_s,
            max_s=retry_max_s,
        )
        """Must-arrive messages going up, kept until the hub acknowledges them."""
        self.seen = Seen(SEEN_IDS)
        """Must-arrive ids that came down, handled once each."""
        self._down_since: float | None = None
        self.robocan = StatusThrottle(robocan_every_s)
        """Rate of robocan_status going up."""
        self._watch: asyncio.Task[None] | None = None

    async def on_start(self) -> None:
        for type_ in UP_TYPES:
            self.subscribe(self.onboard, type_, self._up)
        for type_ in DOWN_TYPES:
            self.subscribe(self.upstream, type_, self._down)
        self.subscribe(self.upstream, ACK, self._acked)
        self.on_cleanup(self.upstream.on_connect(self._connected))
        if not self.upstream.connected.is_set():
            self.courier.pause()  # not connected yet: the first connection resumes it
        on_disconnect = getattr(self.upstream, "on_disconnect", None)
        if callable(on_disconnect):
            self.on_cleanup(on_disconnect(self._disconnected))
        else:
            self._watch = self.spawn(self._watch_link(), name="link")

    async def on_stop(self) -> None:
        self.courier.close()

    async def _watch_link(self) -> None:
        """Notes when the link drops, for an upstream without ``on_disconnect``."""
        while True:
            await self.upstream.connected.wait()
            # The hub client has no "disconnected" event: poll its flag (cheap, 10 Hz).
            while self.upstream.connected.is_set():  # noqa: ASYNC110
                await asyncio.sleep(0.1)
            self._disconnected()

    @property
    def resent(self) -> int:
        """Must-arrive messages sent again because no acknowledgement came."""
        return self.courier.retries

    def _disconnected(self) -> None:
        if self._down_since is None:
            self._down_since = time.monotonic()
        self.courier.pause()
        log.warning("%s: link down; reports are queued until it is back", self.robot)
        if self.on_disconnect_callback is not None:
            self.on_disconnect_callback()

    def _connected(self) -> None:
        self.connections += 1
        log.info("%s: link up (connection %d)", self.robot, self.connections)
        self._down_since = None
        self.robocan.reset()
        # Unacknowledged messages sent before the drop go again; those queued offline were
        # just flushed by the hub client.
        self.courier.resume()
        if self.on_connect_callback is not None:
            self.on_connect_callback()

    def _up(self, message: Message) -> None:
        if message.source == self.onboard.name:
            return  # came down from the hub: never echo it back
        if message.correlation_id is None:
            self._requesters[message.id] = message.source
            if len(self._requesters) > MAX_PENDING_REPLIES:
                self._requesters.popitem(last=False)
        if message.type in LIVE_ONLY and not self.upstream.connected.is_set():
            return  # monitoring would crowd the reports out of the bounded offline queue
        if message.type == "robocan_status" and not self.robocan.allow(message, time.monotonic()):
            return
        self.sent_up += 1
        if message.type in MUST_ARRIVE_UP:
            self.courier.post(message)
        else:
            self.upstream.send(message)

    def _acked(self, message: Message) -> None:
        self.courier.on_ack(message)

    def _down(self, message: Message) -> None:
        if message.destination not in (None, self.upstream.name, self.robot):
            return
        if message.type in ADDRESSED_ONLY and message.destination is None:
            return  # a kill meant for the server's RGM (or anyone) is not for this robot
        if message.type == "error" and message.source == "hub":
            # The hub refused one of ours: a copy would be refused again, stop sending it.
            if self.courier.on_ack(message):
                log.warning("%s: the hub refused a message: %s", self.robot, message.payload)
        if message.type in MUST_ARRIVE_DOWN and message.destination is not None:
            # Every copy is acknowledged (the first ack may be lost); one id is handled once.
            self.upstream.send(ack_for(message, self.upstream.name))
            if not self.seen.first(message.id):
                return
        requester = self._requesters.get(message.correlation_id or "")
        typed = _typed_at_the_edge(message)
        local = Message(
            type=message.type,
            id=message.id,
            timestamp=message.timestamp,
            source=self.onboard.name,
            destination=requester,
            correlation_id=message.correlation_id,
            payload=dict(message.payload or {}),
        )
        if typed is not None:
            local.keep_typed(typed)
        self.sent_down += 1
        if self.on_message_down is not None:
            self.on_message_down(local)
        self.onboard.bus.publish(local)
