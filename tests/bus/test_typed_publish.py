"""Senders publish payload models: the type name comes from the model's registration."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from guidebot.bus import Bus
from guidebot.messages import Message, make_message, type_name
from guidebot.payloads.petri import Say, SpeechEnded
from guidebot.payloads.robot import BatteryAlarm


def test_a_payload_model_brings_its_type_name() -> None:
    bus = Bus()
    a, b = bus.endpoint("a"), bus.endpoint("b")
    got: list[Message] = []
    b.subscribe("say", got.append)
    sent = a.publish(Say(text="hello"))
    assert sent.type == "say" and got == [sent]
    assert got[0].payload == {"text": "hello", "lang": "en"}
    assert got[0].payload_as(Say) == Say(text="hello")


def test_a_model_bound_to_several_types_needs_the_type_name() -> None:
    alarm = BatteryAlarm(robot="R1", level=0.1)
    with pytest.raises(TypeError, match="battery_low, battery_panic: give the type name"):
        make_message(alarm)
    assert make_message("battery_panic", alarm).payload == {"robot": "R1", "level": 0.1}


def test_a_model_is_refused_for_another_type() -> None:
    with pytest.raises(TypeError, match="'say' carries Say, not SpeechEnded"):
        make_message("say", SpeechEnded(text="x"))
    with pytest.raises(TypeError, match="either a payload model or a type name"):
        make_message(Say(text="x"), {"text": "y"})
    assert type_name(Say) == "say"


def test_a_sender_mistake_raises_at_the_sender() -> None:
    with pytest.raises(ValidationError):
        Say(text="hi", volume=3)  # type: ignore[call-arg]


async def test_request_and_reply_take_models_too() -> None:
    bus = Bus()
    asker, speaker = bus.endpoint("asker"), bus.endpoint("speaker")
    speaker.subscribe("say", lambda m: speaker.reply(m, SpeechEnded(text=m.payload["text"])))
    reply = await asker.request(Say(text="hi"), destination="speaker", timeout=5.0)
    assert reply.type == "speech_ended" and reply.payload_as(SpeechEnded).text == "hi"
