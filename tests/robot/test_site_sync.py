"""The robot follows site_changed without stalling its event loop: a version is read (validated,
its route graph built) in a thread, one at a time, the newest of those waiting next."""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import pytest

from guidebot.bus import Bus
from guidebot.site.schema import Site
from guidebot.site.synthetic import synthetic_site
from robot_agent.agent import onboard_site
from robot_agent.site_sync import SiteFollower

WAIT = 10.0


def site_doc() -> dict[str, Any]:
    doc = synthetic_site(nodes=50, robots=2, areas=1, pois=3, floors=2).model_dump(mode="json")
    for robot in doc["robots"]:
        del robot["token"]  # the robots' view of a site carries no tokens
    return doc


async def until(check: Any) -> None:
    deadline = time.monotonic() + WAIT
    while not check():
        assert time.monotonic() < deadline, "not reached in time"
        await asyncio.sleep(0.01)


async def test_a_slow_site_is_read_off_the_loop_and_only_the_newest_waiting_one_next() -> None:
    bus = Bus()
    server = bus.endpoint("server")
    loaded: list[int] = []
    server.subscribe("site_loaded", lambda m: loaded.append(m.payload["version"]))
    read_in: list[tuple[str, int]] = []
    applied: list[Any] = []
    release = threading.Event()

    def prepare(site: Site) -> Any:
        read_in.append((threading.current_thread().name, len(site.nodes)))
        release.wait(WAIT)  # a big site: seconds of work
        return onboard_site(site)

    follower = SiteFollower(bus.endpoint("site"), "R0", applied.append, prepare=prepare)
    doc = site_doc()
    async with follower:
        server.publish("site_changed", {"version": 1, "site": doc})
        await until(lambda: len(read_in) == 1)
        # The loop runs on while version 1 is read (this line runs while prepare() waits for
        # the release only this test gives); 2 and 3 arrive meanwhile.
        server.publish("site_changed", {"version": 2, "site": doc})
        server.publish("site_changed", {"version": 3, "site": doc})
        await asyncio.sleep(0.05)
        assert follower.version == 0 and applied == []
        release.set()
        await until(lambda: follower.version == 3)
    assert len(read_in) == 2  # version 2 was never read: 3 had replaced it
    assert all(name != threading.main_thread().name for name, _ in read_in)
    assert [view.planner("n0_0_0", "n1_1_1")["nodes"][-1] for view in applied] == ["n1_1_1"] * 2
    assert loaded == [1, 3]


async def test_a_refused_version_keeps_the_one_running() -> None:
    bus = Bus()
    server = bus.endpoint("server")
    loaded: list[int] = []
    server.subscribe("site_loaded", lambda m: loaded.append(m.payload["version"]))
    applied: list[Any] = []
    follower = SiteFollower(bus.endpoint("site"), "R0", applied.append)
    async with follower:
        server.publish("site_changed", {"version": 1, "site": site_doc()})
        await until(lambda: follower.version == 1)
        broken = site_doc()
        broken["edges"].append({"a": "n0_0_0", "b": "nowhere"})
        server.publish("site_changed", {"version": 2, "site": broken})
        server.publish("site_changed", {"version": 3, "site": site_doc()})
        await until(lambda: follower.version == 3)
    assert loaded == [1, 3]
    assert [type(site) for site in applied] == [Site, Site]


async def test_a_version_that_breaks_the_reading_is_logged_and_the_next_still_read(
    caplog: pytest.LogCaptureFixture,
) -> None:
    bus = Bus()
    server = bus.endpoint("server")
    calls: list[int] = []

    def prepare(site: Site) -> Site:
        calls.append(len(calls) + 1)
        if len(calls) == 1:
            raise RuntimeError("graph build failed")
        return site

    follower = SiteFollower(bus.endpoint("site"), "R0", lambda _: None, prepare=prepare)
    async with follower:
        server.publish("site_changed", {"version": 1, "site": site_doc()})
        await until(lambda: len(calls) == 1)
        server.publish("site_changed", {"version": 2, "site": site_doc()})
        await until(lambda: follower.version == 2)
    assert "R0: site version 1 could not be read" in caplog.text
