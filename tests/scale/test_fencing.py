"""Fencing (docs/scaling.md): a leader whose lease ran out decides nothing, even before it
notices that it lost the lock. Real PostgreSQL, the real hub bus and Traffic Manager; the lease
is blocked by stopping the leader's renewals, the way a paused process stops them."""

from __future__ import annotations

import asyncio

import pytest

from backend.db import DbStore, make_engine, make_sessionmaker
from backend.db.session import migrate
from backend.fencing import FencedEndpoint
from backend.hub.core import Hub
from backend.leadership import Leadership
from backend.traffic.manager import TrafficManager
from bench.servers import DEMO, wait_until
from guidebot.messages import Message
from guidebot.site.yamlio import load_site_file
from tests.server.postgres import PostgresServer


async def _true(value: object) -> object:
    return value


async def test_a_leader_past_its_lease_grants_nothing(postgres: PostgresServer) -> None:
    db = postgres.database()
    lost: list[str] = []
    alpha = Leadership(db, "alpha", on_lost=lambda: lost.append("alpha"), poll_s=0.2, lease_s=1.0)
    beta = Leadership(db, "beta", on_lost=lambda: lost.append("beta"), poll_s=0.2, lease_s=1.0)
    hub = Hub()
    fenced = FencedEndpoint(hub.endpoint("traffic_manager"), alpha.may_decide)
    traffic = TrafficManager(fenced, load_site_file(DEMO))
    robots = {name: hub.endpoint(name) for name in ("R1", "R2")}
    granted: list[Message] = []
    for endpoint in robots.values():
        endpoint.subscribe("area_granted", granted.append)
    await alpha.start()
    try:
        await asyncio.wait_for(alpha.won.wait(), 30)
        await beta.start()
        await traffic.start()
        assert alpha.may_decide()
        # While the lease runs the fenced Traffic Manager grants as usual.
        robots["R1"].publish("request_area", {"robot": "R1", "area": "corridor"})
        assert [(m.destination, m.payload["area"]) for m in granted] == [("R1", "corridor")]
        robots["R1"].publish("release_area", {"robot": "R1", "area": "corridor"})

        alpha.poll_s = 3600.0  # its renewals stop, as when the process is paused
        await wait_until(lambda: _true(beta.leading), 30, "beta to win the lock")
        assert beta.epoch == (alpha.epoch or 0) + 1
        assert alpha.leading and not alpha.may_decide()  # it has not noticed, but is fenced
        robots["R2"].publish("request_area", {"robot": "R2", "area": "corridor"})
        fenced.publish("area_granted", {"robot": "R2", "area": "corridor"}, destination="R2")
        assert [m.destination for m in granted] == ["R1"]  # nothing for R2 from the old leader
        assert fenced.dropped == 2
        assert traffic.locks.holder("corridor") is None  # the request was not even handled
        report = alpha.report()
        assert report["leading"] and not report["may_decide"]
    finally:
        await traffic.stop()
        await alpha.stop()
        await beta.stop()


def test_the_lease_must_cover_two_polls() -> None:
    with pytest.raises(ValueError, match="at least twice the poll"):
        Leadership("postgresql+asyncpg://x@127.0.0.1/db", "p", on_lost=print, poll_s=1, lease_s=1.5)


async def test_an_old_leaders_late_writes_are_refused_by_the_leader_row(
    postgres: PostgresServer,
) -> None:
    """A paused leader's write-behind rows flushed after another process took the lead (the
    leader row's epoch moved on) are not written; the current leader's are."""
    db = postgres.database()
    alpha = Leadership(db, "alpha", on_lost=lambda: None, poll_s=0.2, lease_s=1.0)
    beta = Leadership(db, "beta", on_lost=lambda: None, poll_s=0.2, lease_s=1.0)
    engine = make_engine(db)
    await migrate(engine)
    await alpha.start()
    try:
        await asyncio.wait_for(alpha.won.wait(), 30)
        old = DbStore(make_sessionmaker(engine), epoch=alpha.fencing_epoch)
        old.record_event("area_granted", "traffic_manager", {"robot": "R1", "area": "corridor"})
        await old.flush()  # alpha leads: written
        assert old.written == 1 and old.fenced == 0

        alpha.poll_s = 3600.0  # paused: its renewals stop, beta takes the lock
        await beta.start()
        await wait_until(lambda: _true(beta.leading), 30, "beta to win the lock")
        assert alpha.leading  # it has not noticed yet
        old.record_event("area_granted", "traffic_manager", {"robot": "R2", "area": "corridor"})
        await old.flush()
        assert old.written == 1 and old.fenced == 1

        new = DbStore(make_sessionmaker(engine), epoch=beta.fencing_epoch)
        new.record_event("area_granted", "traffic_manager", {"robot": "R3", "area": "corridor"})
        await new.flush()
        granted = [e["data"]["robot"] for e in await new.events(kind="area_granted")]
        assert sorted(granted) == ["R1", "R3"]
    finally:
        await alpha.stop()
        await beta.stop()
        await engine.dispose()
