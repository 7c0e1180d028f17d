"""Which hub messages the event log keeps (docs/server.md "Events"), and the endpoint that
copies them into it. Task changes and lock changes are logged by their managers directly."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

from pydantic import ValidationError

from backend.elevator_calls import CallNews
from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.building import ElevatorState

__all__ = ["LOGGED_BROADCASTS", "LOGGED_TYPES", "keep_in_log"]

LOGGED_TYPES = (
    "battery_low",
    "battery_panic",
    "robot_fault",
    "area_yield",
    "robot_connected",
    "robot_disconnected",
    "call_elevator",  # the reports' elevator waits: a call until its elevator_in_position
)
"""Hub messages copied into the event log (task changes and lock changes are logged directly)."""
LOGGED_BROADCASTS = ("door_opened", "door_closed", "elevator_in_position", "node_reached")
"""Also logged, broadcasts only (not the replies to one requester): the fleet's safety
invariants are checked on them (guidebot/invariants.py, docs/server.md "Events")."""


def keep_in_log(
    logger: Endpoint, record_event: Callable[[str, str, dict[str, Any]], object]
) -> None:
    """Subscribe ``logger`` (a hub endpoint) so that the logged types reach ``record_event``;
    an elevator call only when it is news (backend/elevator_calls.py)."""
    calls = CallNews()

    def log_message(msg: Message) -> None:
        if msg.type == "call_elevator" and not calls.is_news(
            str(msg.payload.get("elevator")), str(msg.payload.get("floor"))
        ):
            return  # a press again (backend/elevator_calls.py)
        record_event(msg.type, msg.source, msg.payload)

    def cabin(msg: Message) -> None:
        with contextlib.suppress(ValidationError):
            calls.cabin(msg.payload_as(ElevatorState))

    logger.subscribe("elevator_state", cabin)
    for pattern in LOGGED_TYPES:
        logger.subscribe(pattern, log_message, tap=True)
    for pattern in LOGGED_BROADCASTS:
        logger.subscribe(pattern, log_message)
