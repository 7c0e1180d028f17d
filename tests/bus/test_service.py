"""The one service life cycle (guidebot/service.py): what start takes, stop gives back."""

from __future__ import annotations

import asyncio

import pytest

from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.service import Service, cancel_and_wait
from guidebot.testing import wait_until


class Listener(Service):
    """Subscribes, runs a loop, starts a child service; can be told to fail half-way."""

    def __init__(self, bus: Bus, *, fail: bool = False, child: Service | None = None) -> None:
        super().__init__()
        self.endpoint = bus.endpoint("listener")
        self.fail = fail
        self.child = child
        self.seen: list[str] = []
        self.loop_ended = asyncio.Event()
        self.cleaned: list[str] = []

    async def on_start(self) -> None:
        self.subscribe(self.endpoint, "ping", self._on_ping)
        self.spawn(self._loop(), name="listener-loop")
        self.on_cleanup(lambda: self.cleaned.append("sync"))
        self.on_cleanup(self._async_cleanup)
        if self.child is not None:
            await self.enter(self.child)
        if self.fail:
            raise RuntimeError("the device did not answer")

    async def _async_cleanup(self) -> None:
        await asyncio.sleep(0)
        self.cleaned.append("async")

    def _on_ping(self, msg: Message) -> None:
        self.seen.append(msg.payload["n"])

    async def _loop(self) -> None:
        try:
            await asyncio.Event().wait()
        finally:
            self.loop_ended.set()


class Child(Service):
    def __init__(self) -> None:
        super().__init__()
        self.stops = 0

    async def on_stop(self) -> None:
        self.stops += 1


async def test_stop_unsubscribes_cancels_and_awaits_tasks_in_reverse_order() -> None:
    bus = Bus()
    sender = bus.endpoint("sender")
    child = Child()
    service = Listener(bus, child=child)
    await service.start()
    assert service.running and child.running
    sender.publish("ping", {"n": "1"})
    await wait_until(lambda: service.seen == ["1"])

    await service.stop()
    assert service.loop_ended.is_set()  # awaited, not just cancelled
    assert service.cleaned == ["async", "sync"]  # newest first
    assert child.stops == 1 and not child.running
    sender.publish("ping", {"n": "2"})
    await asyncio.sleep(0.05)  # a message that would arrive arrives within the loop's turn
    assert service.seen == ["1"]
    assert not service.running


async def test_stop_twice_and_stop_before_start_are_harmless() -> None:
    bus = Bus()
    child = Child()
    service = Listener(bus, child=child)
    await service.stop()  # never started
    await service.start()
    await service.stop()
    await service.stop()
    assert service.cleaned == ["async", "sync"]
    assert child.stops == 1


async def test_failed_start_gives_back_what_it_took_and_raises() -> None:
    bus = Bus()
    sender = bus.endpoint("sender")
    child = Child()
    service = Listener(bus, fail=True, child=child)
    with pytest.raises(RuntimeError, match="did not answer"):
        await service.start()
    assert not service.running
    assert service.loop_ended.is_set()
    assert service.cleaned == ["async", "sync"]
    assert child.stops == 1 and not child.running
    sender.publish("ping", {"n": "1"})
    await asyncio.sleep(0.05)
    assert service.seen == []
    # The failed start left nothing to give back twice.
    await service.stop()
    assert service.cleaned == ["async", "sync"] and child.stops == 1


async def test_async_with_starts_and_stops_even_when_the_body_fails() -> None:
    bus = Bus()
    service = Listener(bus)
    with pytest.raises(ValueError):
        async with service as entered:
            assert entered is service and service.running
            raise ValueError("visitor pressed cancel")
    assert not service.running and service.loop_ended.is_set()


async def test_async_with_a_failing_start_raises_without_entering() -> None:
    bus = Bus()
    service = Listener(bus, fail=True)
    entered = False
    with pytest.raises(RuntimeError):
        async with service:
            entered = True
    assert not entered and service.loop_ended.is_set()


async def test_restart_after_stop_takes_everything_again() -> None:
    bus = Bus()
    sender = bus.endpoint("sender")
    service = Listener(bus)
    await service.start()
    await service.stop()
    service.loop_ended.clear()
    await service.start()
    sender.publish("ping", {"n": "again"})
    await wait_until(lambda: service.seen == ["again"])
    await service.stop()
    assert service.loop_ended.is_set()


async def test_cancel_and_wait_tolerates_none_and_finished_tasks() -> None:
    await cancel_and_wait(None)
    done = asyncio.get_running_loop().create_task(asyncio.sleep(0))
    await done
    await cancel_and_wait(done)
    assert done.done() and not done.cancelled()
