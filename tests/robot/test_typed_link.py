"""The robot's link is the robot's edge (as the hub is the server's): a message from the hub
goes on board with its payload model, validated there once; on-board handlers subscribed by
model get that object, and one whose payload is not its model reaches none of them."""

from __future__ import annotations

from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.payloads.traffic import AreaYield, ClosuresChanged
from robot_agent.link import Link

from .test_modules import _FakeUpstream


async def linked() -> tuple[Bus, _FakeUpstream, Link]:
    """R1's link, started, on a bus of its own, to an upstream the test delivers from."""
    bus = Bus()
    up = _FakeUpstream()
    up.connected.set()
    link = Link(bus.endpoint("link"), up, "R1")
    await link.start()
    return bus, up, link


async def test_a_message_from_the_hub_goes_on_board_typed_once() -> None:
    bus, up, link = await linked()
    onboard = bus.endpoint("navigation")
    kept: list[object] = []
    typed: list[ClosuresChanged] = []
    onboard.subscribe("closures_changed", lambda m: kept.append(m.typed_or_none()))
    onboard.on(ClosuresChanged, lambda _, changed: typed.append(changed))
    up.deliver(Message(type="closures_changed", source="closures", payload={"nodes": ["n1"]}))
    assert [c.nodes for c in typed] == [["n1"]]
    assert kept == typed  # validated by the link, before any on-board handler ran
    await link.stop()


async def test_a_payload_that_is_not_its_model_reaches_no_typed_handler() -> None:
    bus, up, link = await linked()
    onboard = bus.endpoint("navigation")
    raw: list[Message] = []
    typed: list[AreaYield] = []
    onboard.subscribe("area_yield", raw.append)
    onboard.on(AreaYield, lambda _, ask: typed.append(ask))
    up.deliver(Message(type="area_yield", source="traffic", payload={"robot": "R1"}))
    assert [m.payload for m in raw] == [{"robot": "R1"}] and typed == []
    await link.stop()
