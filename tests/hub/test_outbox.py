"""The overflow rule of a client's outbound queue (docs/protocol.md)."""

from __future__ import annotations

import asyncio

import pytest

from backend.hub import Outbox, OutboxOverflow


async def test_keeps_every_message_while_the_client_keeps_up() -> None:
    outbox = Outbox(maxsize=10, coalesce_after=5)
    for i in range(3):
        outbox.put(f"state {i}".encode(), key="R1")
    assert await outbox.get_batch(10) == [b"state 0", b"state 1", b"state 2"]
    assert outbox.superseded == 0


async def test_behind_the_newest_robot_state_replaces_the_queued_one_in_place() -> None:
    outbox = Outbox(maxsize=4, coalesce_after=2)
    outbox.put(b"R1 a", key="R1")
    outbox.put(b"R2 a", key="R2")
    outbox.put(b"R1 b", key="R1")  # 2 queued: from now on states merge
    outbox.put(b"R2 b", key="R2")
    for i in range(100):
        outbox.put(f"R1 {i}".encode(), key="R1")
    assert len(outbox) == 2
    assert await outbox.get_batch(10) == [b"R1 99", b"R2 b"]
    assert outbox.superseded == 102  # R1 b, R2 b and the 100 newer R1 states merged


async def test_other_overflow_raises_and_loses_nothing_queued() -> None:
    outbox = Outbox(maxsize=3, coalesce_after=0)
    for i in range(3):
        outbox.put(f"say {i}".encode())
    with pytest.raises(OutboxOverflow, match="3 messages"):
        outbox.put(b"one too many")
    with pytest.raises(OutboxOverflow):
        outbox.put(b"new robot", key="R9")  # a state with nothing to replace cannot merge
    assert await outbox.get_batch(2) == [b"say 0", b"say 1"]
    assert await outbox.get_batch(2) == [b"say 2"]


async def test_batches_are_capped_in_bytes() -> None:
    outbox = Outbox(maxsize=10)
    for _ in range(5):
        outbox.put(b"x" * 100)
    assert len(await outbox.get_batch(10, max_bytes=250)) == 3


async def test_closing_wakes_the_writer() -> None:
    outbox = Outbox(maxsize=4)
    waiter = asyncio.create_task(outbox.get_batch(4))
    await asyncio.sleep(0)
    outbox.close()
    assert await asyncio.wait_for(waiter, 5) == []
