"""The in-process bus: routing rules every module relies on."""

from __future__ import annotations

import asyncio

import pytest

from guidebot.bus import Bus, RequestTimeout
from guidebot.messages import Message


def test_exact_and_wildcard_subscriptions_receive_matching_types() -> None:
    bus = Bus()
    a, b = bus.endpoint("a"), bus.endpoint("b")
    exact: list[str] = []
    wild: list[str] = []
    a.subscribe("door_opened", lambda m: exact.append(m.type))
    b.subscribe("door_*", lambda m: wild.append(m.type))
    a.publish("door_opened")
    a.publish("door_closed")
    a.publish("robot_state")
    assert exact == ["door_opened"]
    assert wild == ["door_opened", "door_closed"]


def test_destination_limits_delivery_but_taps_see_everything() -> None:
    bus = Bus()
    a, b, monitor = bus.endpoint("a"), bus.endpoint("b"), bus.endpoint("monitor")
    got_a: list[Message] = []
    got_b: list[Message] = []
    tapped: list[Message] = []
    a.subscribe("hello", got_a.append)
    b.subscribe("hello", got_b.append)
    monitor.subscribe("*", tapped.append, tap=True)
    a.publish("hello", {"x": 1}, destination="b")
    assert got_a == [] and [m.payload for m in got_b] == [{"x": 1}]
    assert [m.destination for m in tapped] == ["b"]


def test_failing_handler_does_not_stop_delivery() -> None:
    bus = Bus()
    a, b = bus.endpoint("a"), bus.endpoint("b")
    got: list[str] = []

    def broken(message: Message) -> None:
        raise RuntimeError("boom")

    a.subscribe("t", broken)
    b.subscribe("t", lambda m: got.append(m.source))
    a.publish("t")
    assert got == ["a"]


def test_unsubscribe_and_duplicate_names() -> None:
    bus = Bus()
    a = bus.endpoint("a")
    got: list[str] = []
    unsubscribe = a.subscribe("t", lambda m: got.append(m.type))
    unsubscribe()
    a.publish("t")
    assert got == []
    with pytest.raises(ValueError, match="already connected"):
        bus.endpoint("a")


async def test_request_reply_and_timeout() -> None:
    bus = Bus()
    client, server = bus.endpoint("client"), bus.endpoint("server")
    server.subscribe("get_path", lambda m: server.reply(m, "path", {"nodes": ["a", "b"]}))
    reply = await client.request("get_path", {"to": "b"}, timeout=1.0)
    assert reply.type == "path" and reply.payload == {"nodes": ["a", "b"]}
    with pytest.raises(RequestTimeout):
        await client.request("nobody_answers", timeout=0.05)


async def test_async_subscription_is_bounded_and_drops_oldest() -> None:
    bus = Bus()
    a = bus.endpoint("a")
    async with a.subscription("n", maxsize=2) as sub:
        for i in range(3):
            a.publish("n", {"i": i})
        got = [(await asyncio.wait_for(anext(sub), 1)).payload["i"] for _ in range(2)]
    assert got == [1, 2]
