"""Typed at the edge, typed inside: a handler subscribed by payload model receives that model,
validated once per message however many handlers read it, and never a payload that is not one
(guidebot/messages.py ``Message.typed``, guidebot/bus.py ``BusEndpoint.on``)."""

from __future__ import annotations

import logging

import pytest

from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.payloads.petri import Say
from guidebot.payloads.robot import BatteryAlarm
from guidebot.payloads.tasks import RobotLink
from guidebot.service import Service


def test_a_handler_gets_the_model_the_sender_published() -> None:
    bus = Bus()
    a, b = bus.endpoint("a"), bus.endpoint("b")
    got: list[tuple[Message, Say]] = []
    b.on(Say, lambda message, say: got.append((message, say)))
    said = Say(text="hello")
    sent = a.publish(said)
    assert got == [(sent, said)]
    assert got[0][1] is said  # in-process: the sender's object, not validated again


def test_a_dict_payload_is_validated_once_for_every_handler() -> None:
    bus = Bus()
    a, b, c = bus.endpoint("a"), bus.endpoint("b"), bus.endpoint("c")
    got: list[Say] = []
    b.on(Say, lambda _, say: got.append(say))
    c.on(Say, lambda _, say: got.append(say))
    sent = a.publish("say", {"text": "hi"})
    assert got == [Say(text="hi"), Say(text="hi")]
    assert got[0] is got[1] is sent.typed(Say) is sent.payload_as(Say)
    assert isinstance(got[0], Say) and got[0].lang == "en"


def test_an_invalid_payload_never_reaches_a_typed_handler(caplog: pytest.LogCaptureFixture) -> None:
    bus = Bus()
    a, b = bus.endpoint("a"), bus.endpoint("b")
    typed: list[Say] = []
    plain: list[Message] = []
    b.on(Say, lambda _, say: typed.append(say))
    b.subscribe("say", plain.append)
    with caplog.at_level(logging.WARNING, logger="guidebot.bus"):
        a.publish("say", {"text": 3})
    assert typed == [] and [m.payload for m in plain] == [{"text": 3}]
    assert "dropped 'say' from 'a': its payload is not a Say" in caplog.text


def test_a_model_of_several_types_is_heard_on_each_or_on_those_named() -> None:
    bus = Bus()
    a, b = bus.endpoint("a"), bus.endpoint("b")
    every: list[str] = []
    panics: list[str] = []
    stop = b.on(BatteryAlarm, lambda m, alarm: every.append(f"{m.type}:{alarm.robot}"))
    b.on(BatteryAlarm, lambda m, _: panics.append(m.type), types=["battery_panic"])
    alarm = BatteryAlarm(robot="R1", level=0.1)
    a.publish("battery_low", alarm)
    a.publish("battery_panic", alarm)
    assert every == ["battery_low:R1", "battery_panic:R1"] and panics == ["battery_panic"]
    stop()
    a.publish("battery_low", alarm)
    assert len(every) == 2
    with pytest.raises(ValueError, match="is the payload of"):
        b.on(RobotLink, lambda m, _: None, types=["battery_low"])
    with pytest.raises(TypeError, match="not a registered payload model"):
        b.on(Message, lambda m, _: None)


def test_send_keeps_the_typed_payload_of_a_copied_message() -> None:
    bus = Bus()
    a, b = bus.endpoint("a"), bus.endpoint("b")
    got: list[Say] = []
    b.on(Say, lambda _, say: got.append(say))
    said = Say(text="relayed")
    a.send(Message(type="say", source="elsewhere", payload=said.model_dump()))
    message = Message(type="say", source="elsewhere", payload=said.model_dump())
    message.keep_typed(said)
    a.send(message)
    assert got[1] is said


async def test_a_service_unsubscribes_its_typed_handlers_on_stop() -> None:
    bus = Bus()
    a, b = bus.endpoint("a"), bus.endpoint("b")
    got: list[str] = []

    class Speaker(Service):
        async def on_start(self) -> None:
            self.on(b, Say, self.heard)

        def heard(self, message: Message, say: Say) -> None:
            got.append(say.text)

    async with Speaker():
        a.publish(Say(text="one"))
    a.publish(Say(text="two"))
    assert got == ["one"]


def test_the_typed_payload_is_not_part_of_the_envelope() -> None:
    """Not encoded, not compared: two messages that carry the same JSON are equal."""
    said = Say(text="x")
    bare = Message(type="say", id="1", timestamp=1.0, payload=said.model_dump())
    typed = bare.model_copy()
    typed.keep_typed(said)
    assert typed == bare and typed.model_dump() == bare.model_dump()
    assert typed.typed_or_none() is said and bare.typed_or_none() is None
