"""Large messages (a site for the robots) leave one per turn of the event loop, so that a
publish to many robots never holds the loop for all their sends at once; small ones are not
held (nor are batches of small ones, tests/hub/test_resilience.py: a streaming client)."""

from __future__ import annotations

import asyncio

from backend.auth import Role
from backend.hub import Hub
from backend.hub.session import LARGE_FRAME_BYTES, write_batches


async def _sent_in_turns(size: int, robots: int) -> list[int]:
    """Publish one message of about ``size`` bytes to ``robots`` subscribed clients; the loop
    turn in which each client's frame was handed to its socket."""
    hub = Hub(gc_freeze=False)
    turns = 0

    async def count_turns() -> None:
        nonlocal turns
        while True:
            turns += 1
            await asyncio.sleep(0)

    sent_in: list[int] = []

    async def send(frame: bytes) -> None:
        sent_in.append(turns)

    clients = [hub.attach(f"R{k}", Role.ROBOT) for k in range(robots)]
    for client in clients:
        client.subscribe("site_changed")
        # The welcome, taken here, not sent: a writer that had sent it less than
        # ``streaming_s`` before the publish counts as streaming and lets the loop turn once
        # first (one descheduled between two writers' welcomes on a loaded machine did).
        [welcome] = client.outbox.take(hub.batch_max)
        assert b'"welcome"' in welcome
    counter = asyncio.create_task(count_turns())
    writers = [asyncio.create_task(write_batches(c, send)) for c in clients]
    await asyncio.sleep(0.01)
    hub.endpoint("site_editor").publish("site_changed", {"site": "x" * size})
    for _ in range(10 * robots):
        if len(sent_in) == robots:
            break
        await asyncio.sleep(0)
    for task in (counter, *writers):
        task.cancel()
    await asyncio.gather(counter, *writers, return_exceptions=True)
    hub.close()
    assert len(sent_in) == robots
    return sent_in


async def test_large_messages_leave_one_per_loop_turn() -> None:
    turns = await _sent_in_turns(LARGE_FRAME_BYTES, robots=5)
    assert len(set(turns)) == 5, turns


async def test_small_messages_all_leave_in_the_same_turn() -> None:
    turns = await _sent_in_turns(1000, robots=5)
    assert len(set(turns)) == 1, turns
