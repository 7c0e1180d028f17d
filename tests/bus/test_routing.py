"""Pattern tables and pending requests (guidebot.routing), shared by the bus and HubClient."""

from __future__ import annotations

import asyncio

import pytest

from guidebot.messages import Message
from guidebot.routing import PatternTable, PendingRequests, RequestTimeout, Route, pattern_matches


def _route(pattern: str) -> Route:
    return Route(pattern, lambda m: None)


def test_wildcards_match_shell_style_and_exact_types_match_only_themselves() -> None:
    assert pattern_matches("door_*", "door_opened")
    assert pattern_matches("robot_?tate", "robot_state")
    assert pattern_matches("[ab]", "a")
    assert not pattern_matches("door_*", "close_door")
    assert not pattern_matches("door", "door_opened")


def test_table_finds_exact_routes_first_then_wildcards_in_order() -> None:
    table: PatternTable[Route] = PatternTable()
    everything, doors, opened = _route("*"), _route("door_*"), _route("door_opened")
    for route in (everything, doors, opened):
        table.add(route)
    assert table.matching("door_opened") == (opened, everything, doors)
    assert table.matching("robot_state") == (everything,)
    assert table.patterns() == ["door_opened", "*", "door_*"]


def test_add_and_remove_say_when_a_pattern_starts_and_ends() -> None:
    table: PatternTable[Route] = PatternTable()
    first, second = _route("battery_*"), _route("battery_*")
    assert table.add(first) is True
    assert table.add(second) is False
    assert table.remove(first) is False
    assert table.remove(first) is False  # twice: nothing happens
    assert table.remove(second) is True
    assert table.matching("battery_low") == () and table.patterns() == []


def test_a_distinct_table_keeps_one_route_per_key_until_the_overlap_ends() -> None:
    """The hub's table (key: the WebSocket client): overlapping patterns deliver once."""
    table: PatternTable[Route] = PatternTable(distinct=lambda r: r.pattern[0])
    exact, star, other = _route("robot_state"), _route("r*"), _route("*")
    for route in (star, exact, other):
        table.add(route)
    assert table.matching("robot_state") == (exact, other)  # "r*" is the same key as exact
    assert table.matching("release") == (star, other)
    table.remove(exact)  # the cached answer is dropped with the route
    assert table.matching("robot_state") == (star, other)


async def test_a_request_gets_its_reply_and_only_its_reply() -> None:
    pending = PendingRequests()
    sent: list[Message] = []

    def send(message: Message) -> None:
        sent.append(message)
        assert not pending.resolve(Message(type="answer", correlation_id="someone-else"))
        asyncio.get_running_loop().call_soon(
            pending.resolve, message.reply("answer", {"n": 1}, source="b")
        )

    reply = await pending.wait(Message(type="question"), send, timeout=5.0)
    assert reply.payload == {"n": 1} and reply.correlation_id == sent[0].id
    assert pending.values() == []


async def test_a_request_without_reply_times_out_and_is_forgotten() -> None:
    pending = PendingRequests()
    with pytest.raises(RequestTimeout, match=r"'question' within 0\.01 s"):
        await pending.wait(Message(type="question"), lambda m: None, timeout=0.01)
    assert pending.values() == []


async def test_cancel_all_cancels_the_waiting_requests() -> None:
    pending = PendingRequests()
    task = asyncio.create_task(pending.wait(Message(type="q"), lambda m: None, timeout=60))
    await asyncio.sleep(0)
    pending.cancel_all()
    with pytest.raises(asyncio.CancelledError):
        await asyncio.wait_for(task, 5)


def test_a_route_added_or_removed_after_a_type_was_matched_counts_at_once() -> None:
    table: PatternTable[Route] = PatternTable()
    opened = _route("door_opened")
    table.add(opened)
    assert table.matching("door_opened") == (opened,)
    doors = _route("door_*")
    table.add(doors)
    assert table.matching("door_opened") == (opened, doors)
    table.remove(opened)
    assert table.matching("door_opened") == (doors,)


def test_the_remembered_types_are_bounded() -> None:
    table: PatternTable[Route] = PatternTable()
    everything = _route("*")
    table.add(everything)
    for i in range(PatternTable.CACHE_TYPES * 3):
        assert table.matching(f"type_{i}") == (everything,)
    assert len(table._cache) <= PatternTable.CACHE_TYPES
