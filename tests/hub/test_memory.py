"""The hub's GC policy: freeze after clients connect, reclaim after enough of them left, and
never a pass over everything frozen while the hub serves."""

from __future__ import annotations

import asyncio
import gc
from collections.abc import Iterator

import pytest

from backend.auth import Role
from backend.hub import Hub
from backend.hub.memory import GcFreezer
from backend.site.offloop import gc_paused
from backend.testing import RunningServer
from guidebot.testing import wait_until

from .conftest import ClientFactory


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


class FakeClock:
    """Monotonic seconds the test moves by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def collections(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The generations of every gc.collect() call (2: a full pass over everything unfrozen)."""
    calls: list[int] = []
    real = gc.collect

    def recorded(generation: int = 2) -> int:
        calls.append(generation)
        return real(generation)

    monkeypatch.setattr(gc, "collect", recorded)
    return calls


def one_leave_policy(clock: FakeClock, **overrides: float) -> GcFreezer:
    """A freezer whose reclaim falls due at the first leave, timed by ``clock``."""
    settings: dict[str, float] = {"min_interval_s": 0, **overrides}
    return GcFreezer(delay=0, min_churn=1, churn_ratio=0.1, clock=clock, **settings)  # type: ignore[arg-type]


async def frozen(freezer: GcFreezer, connected: int) -> None:
    freezer.attached(connected)
    await wait_until(lambda: freezer.freezes == 1)


async def test_clients_leaving_never_collect_on_their_way_out(collections: list[int]) -> None:
    """The reclaim (a full pass: 0.7-2 s with a large site) is due after a quarter of the
    clients left, and runs later on its own timer, not inside a leave (a reconnect storm)."""
    clock = FakeClock()
    freezer = GcFreezer(
        delay=0, min_churn=3, churn_ratio=0.5, quiet_s=5.0, min_interval_s=0, clock=clock
    )
    await frozen(freezer, 4)
    collections.clear()
    freezer.detached(3)
    freezer.detached(2)
    assert not freezer.reclaim_due  # 2 of 4 gone is under min_churn
    freezer.detached(1)
    assert freezer.reclaim_due and freezer.reclaims == 0
    assert collections == []  # nothing collected while the clients left
    freezer._reclaim()  # its timer, early: the hub has not been quiet for quiet_s
    assert freezer.reclaims == 0 and collections == []
    clock.now += 5.0
    freezer._reclaim()
    assert freezer.reclaims == 1 and collections == [2] and not freezer.reclaim_due
    assert gc.get_freeze_count() > 0  # frozen again at once: later full passes stay short
    freezer.detached(0)
    assert not freezer.reclaim_due  # counting starts again
    freezer.stop()
    assert gc.get_freeze_count() == 0


async def test_the_timer_runs_the_reclaim_once_the_hub_is_quiet() -> None:
    freezer = GcFreezer(delay=0, min_churn=1, churn_ratio=0.1, quiet_s=0.01, min_interval_s=0)
    await frozen(freezer, 2)
    freezer.detached(1)
    assert freezer.reclaim_due
    await wait_until(lambda: freezer.reclaims == 1)
    freezer.stop()


async def test_a_reclaim_waits_for_clients_to_settle_but_not_for_ever() -> None:
    clock = FakeClock()
    freezer = one_leave_policy(clock, quiet_s=5.0, max_wait_s=60.0)
    await frozen(freezer, 2)
    freezer.detached(1)
    for _ in range(11):  # a client comes or goes every 4 s: never quiet for 5 s
        clock.now += 4.0
        freezer.attached(2)
        freezer._reclaim()
    assert freezer.reclaims == 0
    clock.now += 16.0  # 60 s since it fell due
    freezer.attached(2)
    freezer._reclaim()
    assert freezer.reclaims == 1
    freezer.stop()


async def test_reclaims_are_spaced_by_their_own_cost(monkeypatch: pytest.MonkeyPatch) -> None:
    """A pass of D seconds is followed by none for D / max_duty seconds (nor min_interval_s):
    the reclaim holds the loop for at most max_duty of its time."""
    clock, watch = FakeClock(), FakeClock()
    real_collect = gc.collect

    def slow_collect(generation: int = 2) -> int:
        watch.now += 2.0  # a 2 s pass, as with a large site on a busy VM
        return real_collect(generation)

    freezer = one_leave_policy(clock, quiet_s=0, min_interval_s=300.0, max_duty=0.001)
    freezer.stopwatch = watch
    await frozen(freezer, 3)
    monkeypatch.setattr(gc, "collect", slow_collect)
    freezer.detached(2)
    freezer._reclaim()
    assert freezer.reclaims == 1 and freezer.last_reclaim_s == 2.0
    freezer.detached(1)
    assert freezer.reclaim_due
    clock.now += 1999.0
    freezer._reclaim()
    assert freezer.reclaims == 1  # 2 s / 0.1 % = 2000 s
    clock.now += 1.0
    freezer._reclaim()
    assert freezer.reclaims == 2
    freezer.stop()


async def test_waits_while_site_work_has_the_collector_paused() -> None:
    """A freeze or a reclaim due while the collector is paused would walk everything the site
    work allocated, on the loop: both wait until it is back on."""
    freezer = GcFreezer(delay=0.01, min_churn=1, churn_ratio=0.5, quiet_s=0, min_interval_s=0)
    with gc_paused():
        freezer.attached(2)
        await asyncio.sleep(0.05)
        assert freezer.freezes == 0
    await wait_until(lambda: freezer.freezes == 1)
    with gc_paused():
        freezer.detached(1)
        freezer._reclaim()
        assert freezer.reclaims == 0 and freezer.reclaim_due
    await wait_until(lambda: freezer.reclaims == 1)
    freezer.stop()


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


async def test_freezing_does_not_count_the_frozen(monkeypatch: pytest.MonkeyPatch) -> None:
    """gc.get_freeze_count() walks every frozen object (27 ms per 2 million): not on the loop."""

    counts: list[int] = []
    real_count = gc.get_freeze_count

    def counted() -> int:
        counts.append(real_count())
        return counts[-1]

    freezer = GcFreezer(delay=0)
    monkeypatch.setattr(gc, "get_freeze_count", counted)
    freezer.attached(1)
    await asyncio.sleep(0.01)
    assert freezer.freezes == 1
    assert counts == []  # (raising here instead would only reach the loop's exception log)
    monkeypatch.undo()
    freezer.stop()


async def test_clients_that_left_leave_no_cycle_among_the_frozen(
    server: RunningServer, connect: ClientFactory
) -> None:
    """Frozen while connected, then gone: nothing of theirs waits for a pass over everything
    frozen (on asyncio's loop each closed connection left its transport, a cycle through its
    own read callback; such a pass takes 0.9-1.3 s with a large site)."""
    hub = server.app.state.hub
    hub.memory.delay = 3600.0  # frozen below, once every handshake is over
    names = ["R1", "R2", "gui", "op", "panel", "tm"]
    clients = [await connect(who) for who in names]
    for client in clients:
        await client.sync()
    assert hub.memory._timer is not None
    hub.memory._timer.cancel()
    hub.memory._freeze()  # its timer, early: a fleet connected, then frozen
    for client in clients:
        await client.close()
    await wait_until(lambda: not hub.clients)
    await asyncio.sleep(0)  # the transports' connection_lost callbacks run
    gc.collect()  # young garbage (an exception's traceback holding a transport, say)
    gc.unfreeze()  # what is still unreachable now waited for a pass over everything frozen
    gc.set_debug(gc.DEBUG_SAVEALL)
    try:
        gc.collect()
        left = sorted({type(o).__name__ for o in gc.garbage if "Transport" in type(o).__name__})
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
    assert left == []


async def test_a_reclaim_never_walks_the_frozen(monkeypatch: pytest.MonkeyPatch) -> None:
    """The reclaim collects what is not frozen (young cycles of the departures) and freezes
    again; it never unfreezes, which would walk the whole site."""
    clock = FakeClock()
    freezer = one_leave_policy(clock, quiet_s=0)
    await frozen(freezer, 2)
    unfrozen: list[bool] = []
    monkeypatch.setattr(gc, "unfreeze", lambda: unfrozen.append(True))
    cycle: list[object] = []
    cycle.append(cycle)  # young garbage left by a departure
    del cycle
    freezer.detached(1)
    freezer._reclaim()
    assert freezer.reclaims == 1 and freezer.last_reclaimed >= 1
    assert unfrozen == []
    monkeypatch.undo()
    freezer.stop()
