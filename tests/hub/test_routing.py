"""Publish/subscribe, point-to-point and request/reply through a real server."""

from __future__ import annotations

import asyncio

import pytest

from backend.testing import RunningServer
from guidebot.bus import RequestTimeout
from guidebot.client import HubError
from guidebot.messages import Message
from guidebot.payloads.petri import Say

from .conftest import ClientFactory

WAIT = 10.0


class Inbox:
    """Collects messages from a handler so a test can await them in order."""

    def __init__(self) -> None:
        self.queue: asyncio.Queue[Message] = asyncio.Queue()

    def __call__(self, message: Message) -> None:
        self.queue.put_nowait(message)

    async def next(self) -> Message:
        return await asyncio.wait_for(self.queue.get(), WAIT)

    async def take(self, n: int) -> list[Message]:
        return [await self.next() for _ in range(n)]


async def test_messages_of_one_publisher_arrive_in_order(connect: ClientFactory) -> None:
    gui, r1 = await connect("gui"), await connect("R1")
    inbox = Inbox()
    gui.subscribe("say", inbox)
    await gui.sync()
    for i in range(300):
        r1.publish("say", {"text": str(i)})
    received = await inbox.take(300)
    assert [m.payload["text"] for m in received] == [str(i) for i in range(300)]
    assert {m.source for m in received} == {"R1"}


async def test_wildcard_subscription_matches_by_type(connect: ClientFactory) -> None:
    gui, r1 = await connect("gui"), await connect("R1")
    battery, everything = Inbox(), Inbox()
    gui.subscribe("battery_*", battery)
    gui.subscribe("*", everything)
    await gui.sync()
    r1.publish("say", {"text": "hello"})
    r1.publish("battery_low", {"robot": "R1", "level": 0.2})
    r1.publish("battery_panic", {"robot": "R1", "level": 0.05})
    assert [m.type for m in await battery.take(2)] == ["battery_low", "battery_panic"]
    # "*" and "battery_*" both match: the message is delivered once per handler, not twice.
    types = [m.type for m in await everything.take(3)]
    assert types == ["say", "battery_low", "battery_panic"]
    assert everything.queue.empty()


async def test_unsubscribe_stops_delivery(connect: ClientFactory) -> None:
    gui, r1 = await connect("gui"), await connect("R1")
    inbox = Inbox()
    unsubscribe = gui.subscribe("say", inbox)
    await gui.sync()
    r1.publish("say", {"text": "one"})
    assert (await inbox.next()).payload["text"] == "one"
    unsubscribe()
    marker = Inbox()
    gui.subscribe("battery_low", marker)
    await gui.sync()
    r1.publish("say", {"text": "two"})
    r1.publish("battery_low", {"robot": "R1", "level": 0.2})
    await marker.next()  # sent after "two" by the same publisher: "two" was not delivered
    assert inbox.queue.empty()


async def test_point_to_point_reaches_only_the_destination(connect: ClientFactory) -> None:
    tm, r1, r2, gui = (
        await connect("tm"),
        await connect("R1"),
        await connect("R2"),
        await connect("gui"),
    )
    r1_inbox, r2_inbox, gui_inbox = Inbox(), Inbox(), Inbox()
    r1.subscribe("task_assigned", r1_inbox)
    r2.subscribe("task_assigned", r2_inbox)
    gui.subscribe("*", gui_inbox)
    await asyncio.gather(r1.sync(), r2.sync(), gui.sync())
    tm.publish(
        "task_assigned", {"task_id": "t1", "robot": "R2", "net": "give_tour"}, destination="R2"
    )
    got = await r2_inbox.next()
    assert got.payload["task_id"] == "t1" and got.source == "tour_module"
    await asyncio.gather(r1.sync(), gui.sync())
    assert r1_inbox.queue.empty() and gui_inbox.queue.empty()


async def test_direct_message_needs_no_subscription(connect: ClientFactory) -> None:
    tm, r1 = await connect("tm"), await connect("R1")
    inbox = Inbox()
    r1.subscribe("task_cancel", inbox)  # only the handler filters; the hub delivers anyway
    await r1.sync()
    unsubscribed: list[Message] = []
    tm.publish("task_cancel", {"task_id": "t9"}, destination="R1")
    assert (await inbox.next()).payload["task_id"] == "t9"
    assert not unsubscribed


async def test_request_reply_between_websocket_clients(connect: ClientFactory) -> None:
    tm, r1 = await connect("tm"), await connect("R1")

    def answer(request: Message) -> None:
        tm.reply(request, "path", {"nodes": ["A", request.payload["to_node"]], "length_m": 3.5})

    tm.subscribe("get_path", answer)
    await tm.sync()
    reply = await r1.request("get_path", {"robot": "R1", "to_node": "B"}, timeout=WAIT)
    assert reply.type == "path"
    assert reply.payload["nodes"] == ["A", "B"]
    assert reply.source == "tour_module" and reply.destination == "R1"


async def test_request_times_out_without_a_replier(connect: ClientFactory) -> None:
    r1 = await connect("R1")
    with pytest.raises(RequestTimeout):
        await r1.request("get_path", {"robot": "R1", "to_node": "B"}, timeout=0.3)
    await r1.sync()  # the connection is still fine


async def test_request_to_unknown_destination_is_refused(connect: ClientFactory) -> None:
    r1 = await connect("R1")
    with pytest.raises(HubError) as refused:
        await r1.request("open_door", {"door": "D1"}, destination="nobody", timeout=WAIT)
    assert refused.value.code == "unknown_destination"


async def test_in_process_module_and_websocket_client_talk(
    server: RunningServer, connect: ClientFactory
) -> None:
    """The Task Manager runs in the server process and uses the hub's in-process endpoint."""
    hub = server.app.state.hub
    traffic = hub.endpoint("traffic_manager")
    seen: list[Message] = []
    traffic.subscribe("robot_state", seen.append)
    traffic.subscribe(
        "get_path", lambda m: traffic.reply(m, "path", {"nodes": [m.payload["to_node"]]})
    )
    r1 = await connect("R1")
    reply = await r1.request("get_path", {"robot": "R1", "to_node": "Z"}, timeout=WAIT)
    assert reply.payload["nodes"] == ["Z"]
    r1.publish("robot_state", {"robot": "R1", "x": 1.0, "seq": 1})
    await r1.sync()
    assert [m.payload["seq"] for m in seen] == [1]
    assert seen[0].source == "R1"

    # and the other way round: a module's request answered by the robot
    def arrive(request: Message) -> None:
        r1.reply(request, "goal_reached", {"node": request.payload["node"]})

    r1.subscribe("navigate_to", arrive)
    await r1.sync()
    answer = await traffic.request("navigate_to", {"node": "N7"}, destination="R1", timeout=WAIT)
    assert answer.type == "goal_reached" and answer.payload == {"node": "N7"}
    traffic.close()


async def test_client_subscription_is_a_bounded_async_iterator(connect: ClientFactory) -> None:
    gui, r1 = await connect("gui"), await connect("R1")
    async with gui.subscription("say", maxsize=2) as said:
        await gui.sync()
        for i in range(3):
            r1.publish(Say(text=str(i)))
        await r1.sync()
        await gui.sync()  # all three reached the gui: the first was dropped for the newest
        got = [(await asyncio.wait_for(anext(said), WAIT)).payload["text"] for _ in range(2)]
    assert got == ["1", "2"]
