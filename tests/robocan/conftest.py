"""Fixtures for RoboCAN tests: an on-board bus, a unique virtual CAN channel, a watcher."""

from __future__ import annotations

import itertools
import time
from collections.abc import AsyncIterator, Callable, Iterator
from typing import TypeVar

import pytest

from guidebot.bus import Bus, Endpoint
from guidebot.messages import Message
from guidebot.testing import Recorder
from robot_agent.robocan.sim import SimModule
from robot_agent.robocan.stack import RoboCanStack

from .rawslave import Tap

_channels = itertools.count()
M = TypeVar("M", bound=SimModule)


class Watch(Recorder):
    """Everything published on the on-board bus, with waiting on a condition (no sleeps)."""

    def __init__(self, endpoint: Endpoint) -> None:
        super().__init__(endpoint, "*")

    def status(self, module_id: int, state: str) -> Callable[[Message], bool]:
        return lambda m: m.payload["module_id"] == module_id and m.payload["state"] == state


def sim_module(stack: RoboCanStack, module_id: int, cls: type[M]) -> M:
    """The simulated module behind an ID, as its class."""
    assert stack.simulator is not None
    module = stack.simulator.modules[module_id]
    assert isinstance(module, cls)
    return module


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
