"""The one bounded queue (guidebot.queues): merging, batching, both overflow rules."""

from __future__ import annotations

import asyncio

import pytest

from guidebot.queues import KeyedQueue, QueueOverflow


def test_keyed_items_merge_in_place_once_behind() -> None:
    queue: KeyedQueue[bytes] = KeyedQueue(10, coalesce_after=2)
    queue.put(b"R1 a", "R1")
    queue.put(b"R1 b", "R1")  # 1 queued: not behind yet, both kept
    queue.put(b"say", None)
    queue.put(b"R1 c", "R1")  # 3 queued: replaces the newest R1 in place
    assert queue.take(10) == [b"R1 a", b"R1 c", b"say"]
    assert queue.superseded == 1


def test_drop_oldest_counts_and_keeps_the_newest(caplog: pytest.LogCaptureFixture) -> None:
    queue: KeyedQueue[bytes] = KeyedQueue(3, drop_oldest=True, name="R1 send queue")
    queue.put(b"state", "R1")
    for text in (b"a", b"b", b"c"):
        queue.put(text)
    assert queue.dropped == 1
    assert "R1 send queue: queue full (3), oldest item dropped" in caplog.text
    # The dropped state no longer merges: a new one queues (and drops the oldest again).
    queue.put(b"state 2", "R1")
    assert queue.take(10) == [b"b", b"c", b"state 2"]
    assert queue.dropped == 2


def test_overflow_without_drop_oldest_raises_and_loses_nothing() -> None:
    queue: KeyedQueue[bytes] = KeyedQueue(2)
    queue.put(b"1")
    queue.put(b"2")
    with pytest.raises(QueueOverflow, match="2 messages"):
        queue.put(b"3")
    assert queue.take(10) == [b"1", b"2"] and queue.dropped == 0


def test_batches_stop_at_a_count_or_a_size() -> None:
    queue: KeyedQueue[bytes] = KeyedQueue(10)
    for _ in range(5):
        queue.put(b"x" * 100)
    assert len(queue.take(2)) == 2
    assert len(queue.take(10, max_bytes=150)) == 2  # the second goes over: then it stops
    assert len(queue.take(10)) == 1


def test_requeue_puts_an_unsent_batch_back_in_front_keys_and_all() -> None:
    queue: KeyedQueue[bytes] = KeyedQueue(10)
    queue.put(b"state 1", "R1")
    queue.put(b"say")
    batch = queue.take_entries(10)
    queue.put(b"later")
    queue.requeue(batch)
    queue.put(b"state 2", "R1")  # merges into the requeued state
    assert queue.take(10) == [b"state 2", b"say", b"later"]


def test_a_zero_size_queue_is_refused() -> None:
    with pytest.raises(ValueError, match="at least one"):
        KeyedQueue(0)


async def test_linger_returns_early_once_enough_are_queued() -> None:
    queue: KeyedQueue[bytes] = KeyedQueue(10)
    waiter = asyncio.create_task(queue.linger(60.0, enough=2))
    queue.put(b"1")
    await asyncio.sleep(0)
    assert not waiter.done()
    queue.put(b"2")
    await asyncio.wait_for(waiter, 5)


async def test_iteration_waits_for_items_and_ends_once_closed_and_drained() -> None:
    queue: KeyedQueue[str] = KeyedQueue(4, drop_oldest=True)
    got: list[str] = []

    async def read() -> None:
        async for item in queue:
            got.append(item)

    reader = asyncio.create_task(read())
    queue.put("a")
    queue.put("b")
    queue.close()
    await asyncio.wait_for(reader, 5)
    assert got == ["a", "b"]
