"""Fixtures for RoboCAN tests: an on-board bus, a unique virtual CAN channel, a watcher."""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import AsyncIterator, Callable, Iterator
from typing import TypeVar

import pytest

from guidebot.bus import Bus, Endpoint
from guidebot.messages import Message
from robot_agent.robocan.sim import SimModule
from robot_agent.robocan.stack import RoboCanStack

from .rawslave import Tap

_channels = itertools.count()
M = TypeVar("M", bound=SimModule)


class Watch:
    """Everything published on the on-board bus, with waiting on a condition (no sleeps)."""

    def __init__(self, endpoint: Endpoint) -> None:
        self.messages: list[Message] = []
        self._changed = asyncio.Event()
        endpoint.subscribe("*", self._on_message)

    def _on_message(self, message: Message) -> None:
        self.messages.append(message)
        self._changed.set()

    def of(self, type_: str) -> list[Message]:
        return [m for m in self.messages if m.type == type_]

    async def wait_for(
        self, type_: str, predicate: Callable[[Message], bool] = lambda m: True, timeout: float = 10
    ) -> Message:
        deadline = time.monotonic() + timeout
        start = 0
        while True:
            for message in self.messages[start:]:
                if message.type == type_ and predicate(message):
                    return message
            start = len(self.messages)
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no {type_} matching the condition within {timeout} s")
            self._changed.clear()
            try:
                await asyncio.wait_for(self._changed.wait(), remaining)
            except TimeoutError:
                pass

    def status(self, module_id: int, state: str) -> Callable[[Message], bool]:
        return lambda m: m.payload["module_id"] == module_id and m.payload["state"] == state


def sim_module(stack: RoboCanStack, module_id: int, cls: type[M]) -> M:
    """The simulated module behind an ID, as its class."""
    assert stack.simulator is not None
    module = stack.simulator.modules[module_id]
    assert isinstance(module, cls)
    return module


async def wait_until(condition: Callable[[], bool], timeout: float = 10.0) -> None:
    """Poll a condition that no message announces (state inside a simulated module)."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError("condition not met in time")
        await asyncio.sleep(0.01)


@pytest.fixture
def channel() -> str:
    return f"virtual:test-robocan-{next(_channels)}-{time.monotonic_ns()}"


@pytest.fixture
def onboard() -> Bus:
    return Bus()


@pytest.fixture
def watch(onboard: Bus) -> Watch:
    return Watch(onboard.endpoint("watch"))


@pytest.fixture
async def stack(onboard: Bus, channel: str, watch: Watch) -> AsyncIterator[RoboCanStack]:
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], time_scale=10.0) as s:
        await s.wait_online()
        yield s


@pytest.fixture
def tap(channel: str) -> Iterator[Tap]:
    """Every frame on the test's channel (the ``stack`` fixture's bus)."""
    t = Tap(channel)
    yield t
    t.close()
