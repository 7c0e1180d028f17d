"""The hub's GC policy: freeze after clients connect, reclaim after enough of them left."""

from __future__ import annotations

import asyncio
import gc
from collections.abc import Iterator

import pytest

from backend.auth import Role
from backend.hub import Hub
from backend.hub.memory import GcFreezer


@pytest.fixture(autouse=True)
def unfrozen() -> Iterator[None]:
    gc.unfreeze()
    yield
    gc.unfreeze()


async def test_freezes_once_after_a_burst_of_connections() -> None:
    freezer = GcFreezer(delay=0.01)
    for n in range(1, 6):
        freezer.attached(n)
    assert freezer.freezes == 0
    await asyncio.sleep(0.05)
    assert freezer.freezes == 1
    assert gc.get_freeze_count() > 0
    freezer.stop()
    assert gc.get_freeze_count() == 0


async def test_churn_unfreezes_and_collects() -> None:
    freezer = GcFreezer(delay=0, min_churn=3, churn_ratio=0.5)
    freezer.attached(4)
    await asyncio.sleep(0.01)
    assert gc.get_freeze_count() > 0
    freezer.detached(3)
    freezer.detached(2)
    assert freezer.reclaims == 0  # 2 of 4 gone is under min_churn
    freezer.detached(1)
    assert freezer.reclaims == 1
    assert gc.get_freeze_count() == 0
    freezer.detached(0)  # not frozen any more: nothing to do
    assert freezer.reclaims == 1


def test_disabled_or_without_a_loop_does_nothing() -> None:
    GcFreezer(enabled=False).attached(1)
    GcFreezer().attached(1)  # no running loop: the hub is driven directly by a unit test
    assert gc.get_freeze_count() == 0


async def test_hub_freezes_after_attach_and_unfreezes_on_close() -> None:
    hub = Hub()
    hub.memory.delay = 0.01
    hub.attach("R1", Role.ROBOT)
    await asyncio.sleep(0.05)
    assert hub.memory.freezes == 1
    assert gc.get_freeze_count() > 0
    hub.close()
    assert gc.get_freeze_count() == 0
