"""A scripted environment that answers the messages nets publish, on a virtual clock.

Used by ``guidebot petri run`` and by tests: it plays head driver, speech, navigation, on-board
GUI and battery with canned replies, delivered on the clock one after another (never inline),
so a net runs end to end without a robot. A reply is ``{"type": T, "payload": {...}}``; payload
strings may use ``${field}`` of the triggering message; ``"each": "servos"`` sends one reply per
entry of a dict field, with ``${key}`` and ``${value}``; ``"delay": s`` waits s seconds first.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from guidebot.bus import Bus, Endpoint
from guidebot.messages import Message
from petri_nets.clock import VirtualClock
from petri_nets.templates import TemplateError, compile_value

__all__ = ["DEFAULT_REPLIES", "Reply", "ScriptedEnvironment", "parse_reply_option"]

Reply = dict[str, Any]

DEFAULT_REPLIES: dict[str, list[Reply]] = {
    "move_servos": [
        {
            "type": "servo_in_position",
            "each": "servos",
            "payload": {"servo": "${key}", "position": "${value}"},
        }
    ],
    "say": [
        {"type": "speech_started", "payload": {"text": "${text}"}},
        {"type": "speech_ended", "payload": {"text": "${text}"}, "delay": 2.0},
    ],
    "face_people": [{"type": "people_faced", "payload": {}, "delay": 1.0}],
    "navigate_to": [{"type": "goal_reached", "payload": {"node": "${node}"}, "delay": 10.0}],
    "ask_continue": [{"type": "continue_answer", "payload": {"answer": "yes"}, "delay": 3.0}],
    "dock": [
        {"type": "docked", "payload": {"station": "${station}"}, "delay": 2.0},
        {"type": "charged", "payload": {"station": "${station}"}, "delay": 60.0},
    ],
}


def parse_reply_option(text: str) -> tuple[str, list[Reply]]:
    """``TYPE=JSON`` (an object or a list of them; ``[]`` means never answer)."""
    message_type, sep, raw = text.partition("=")
    if not sep or not message_type:
        raise ValueError(f"--reply {text!r}: expected TYPE=JSON")
    try:
        value = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise ValueError(f"--reply {message_type}: invalid JSON ({exc.msg})") from None
    replies = value if isinstance(value, list) else [value]
    for reply in replies:
        if not isinstance(reply, dict) or not isinstance(reply.get("type"), str):
            raise ValueError(f'--reply {message_type}: each reply needs a "type"')
    return message_type, replies


class ScriptedEnvironment:
    """An endpoint on ``bus`` that answers as told and records what it saw."""

    def __init__(
        self,
        bus: Bus,
        clock: VirtualClock,
        replies: dict[str, list[Reply]],
        *,
        name: str = "environment",
    ) -> None:
        self.clock = clock
        self.endpoint: Endpoint = bus.endpoint(name)
        self.replies = replies
        self.seen: list[Message] = []
        self._unsubscribe = [self.endpoint.subscribe(t, self._answer) for t in replies]

    def close(self) -> None:
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self.endpoint.close()

    def _answer(self, message: Message) -> None:
        self.seen.append(message)
        delay = 0.0
        for reply in self.replies.get(message.type, []):
            delay += float(reply.get("delay", 0.0))
            each = reply.get("each")
            if each:
                items = message.payload.get(each) or {}
                envs = [{**message.payload, "key": k, "value": v} for k, v in items.items()]
            else:
                envs = [message.payload]
            for env in envs:
                try:
                    payload = compile_value(reply.get("payload", {}))(env)
                except TemplateError as exc:
                    raise ValueError(f"reply to {message.type}: {exc}") from None
                self.clock.call_later(delay, self._sender(reply["type"], payload))

    def _sender(self, message_type: str, payload: dict[str, Any]) -> Callable[[], None]:
        def send() -> None:
            self.endpoint.publish(message_type, payload)

        return send
