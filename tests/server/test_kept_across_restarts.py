"""What staff decided survives a restart; what nobody needs any more does not stay for ever:
robots out of service are kept, the event log is pruned after its retention (docs/server.md,
"Persistence and restart"). Real servers and a real SQLite file."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import httpx
from sqlalchemy import insert, select

from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.db.models import EventRow
from backend.db.store import PRUNE_CHUNK
from backend.testing import running_server
from guidebot.client import HubClient
from guidebot.messages import Message

from .conftest import OPERATOR_TOKEN, server_settings
from .test_api import eventually, robot

DAY = 86400.0


async def test_robots_out_of_service_stay_out_after_a_restart(tmp_path: Path) -> None:
    settings = server_settings(tmp_path)
    staff = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
    async with (
        running_server(settings) as srv,
        httpx.AsyncClient(base_url=srv.url, headers=staff) as http,
    ):
        for name, out in (("R1", True), ("R2", True), ("R2", False)):
            answer = await http.post(f"/api/robots/{name}/service", json={"out_of_service": out})
            assert answer.status_code == 200
    async with (
        running_server(settings) as srv,
        httpx.AsyncClient(base_url=srv.url, headers=staff) as http,
    ):
        robots = {r["name"]: r["out_of_service"] for r in (await http.get("/api/robots")).json()}
        assert robots == {"R1": True, "R2": False, "R3": False}
        manager = srv.app.state.task_manager
        async with robot(srv, "R1", "hall") as r1:
            await eventually(lambda: manager.robots["R1"].online)
            task = (
                await http.post("/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "loom"}})
            ).json()
            assert manager.get(task["id"]).state == "queued"  # the only robot online is out
            back = await http.post("/api/robots/R1/service", json={"out_of_service": False})
            assert back.status_code == 200
            order = await r1.next_order("go_to_poi")
            assert order.payload["task_id"] == task["id"]
    async with running_server(settings) as srv:
        assert not srv.app.state.task_manager.robots["R1"].out_of_service  # back in, kept too


async def seed_events(url: str, rows: list[tuple[float, str, dict[str, str]]]) -> None:
    """Event rows as an earlier server life left them, with their own times."""
    engine = make_engine(url)
    try:
        await migrate(engine)
        async with make_sessionmaker(engine)() as session, session.begin():
            await session.execute(
                insert(EventRow),
                [{"at": at, "kind": kind, "source": "x", "data": data} for at, kind, data in rows],
            )
    finally:
        await engine.dispose()


async def event_kinds(store: DbStore) -> list[tuple[str, dict[str, str]]]:
    async with store.sessionmaker() as session:
        rows = await session.execute(select(EventRow.kind, EventRow.data).order_by(EventRow.id))
        return [(kind, data) for kind, data in rows]


async def test_retention_deletes_old_events_but_keeps_what_the_next_start_replays(
    tmp_path: Path,
) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'events.db'}"
    old, now = time.time() - 40 * DAY, time.time()
    corridor = {"robot": "R1", "area": "corridor"}
    await seed_events(
        url,
        [(old, "node_reached", {"robot": "R1"}) for _ in range(PRUNE_CHUNK + 7)]  # two chunks
        + [
            (old, "server_started", {}),
            (old, "area_granted", {"robot": "R9", "area": "stairs"}),  # an earlier life's
            (old, "server_started", {}),  # this life began 40 days ago
            (old, "area_granted", corridor),  # still held: the next start needs it
            (old, "alert_raised", {"id": "a1"}),  # the console replays alerts at start
            (old, "node_reached", {"robot": "R2"}),
            (now, "node_reached", {"robot": "R3"}),
        ],
    )
    engine = make_engine(url)
    try:
        store = DbStore(make_sessionmaker(engine))
        holders = await store.lock_holders()
        assert holders == {"corridor": "R1"}
        assert await store.prune_events(time.time() - 30 * DAY) == PRUNE_CHUNK + 7 + 3
        assert await event_kinds(store) == [
            ("server_started", {}),
            ("area_granted", corridor),
            ("alert_raised", {"id": "a1"}),
            ("node_reached", {"robot": "R3"}),
        ]
        assert await store.lock_holders() == holders
        assert await store.prune_events(time.time() - 30 * DAY) == 0
    finally:
        await engine.dispose()


async def test_a_running_server_prunes_its_event_log_in_the_background(tmp_path: Path) -> None:
    settings = server_settings(tmp_path).model_copy(
        update={"event_retention_days": 30.0, "event_prune_every_s": 0.05}
    )
    old = time.time() - 31 * DAY
    await seed_events(settings.db_url, [(old, "node_reached", {"robot": "R1"})] * 50)
    async with running_server(settings) as srv:
        store = srv.app.state.store
        await eventually(lambda: store.pruned == 50)
        kinds = [kind for kind, _ in await event_kinds(store)]
        assert "node_reached" not in kinds and "server_started" in kinds


async def test_retention_zero_keeps_every_event(tmp_path: Path) -> None:
    settings = server_settings(tmp_path).model_copy(update={"event_retention_days": 0.0})
    async with running_server(settings) as srv:
        assert srv.app.state.store.retention_s is None


async def test_a_restored_task_its_robot_ended_unheard_is_not_given_out_again(
    tmp_path: Path,
) -> None:
    """The server goes down with a task assigned; the robot runs and ends it meanwhile, and its
    task_started and task_ended are lost (a long freeze overflows its link's queue). Back, it
    names the task among the last it ended (robot_state ``ended``): the task ends there, and
    is not requeued and run a second time by another robot."""
    settings = server_settings(tmp_path)
    staff = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
    async with (
        running_server(settings) as srv,
        httpx.AsyncClient(base_url=srv.url, headers=staff) as http,
    ):
        async with robot(srv, "R1", "hall") as r1:
            task = (
                await http.post(
                    "/api/tasks",
                    json={"kind": "go_to_poi", "params": {"poi": "loom"}, "robot": "R1"},
                )
            ).json()
            await r1.next_order("go_to_poi")
            assert srv.app.state.task_manager.get(task["id"]).state == "assigned"
    async with running_server(settings) as srv:
        manager = srv.app.state.task_manager
        assert manager.get(task["id"]).state == "assigned"  # restored, unconfirmed
        async with (
            robot(srv, "R2", "hall") as r2,
            HubClient(srv.ws_url, "robot-R1-demo-token") as r1,
        ):
            orders: list[Message] = []
            for client in (r1, r2.client):
                client.subscribe("task_assigned", orders.append)
            await r1.sync()
            # Its first word after the reconnect, as a robot agent sends it (robot/state.py).
            ended = [{"task_id": task["id"], "outcome": "done", "reason": ""}]
            r1.publish(
                "robot_state",
                {"robot": "R1", "node": "ga2", "mode": "idle", "task_id": None, "ended": ended},
            )
            await r1.sync()
            await r2.client.sync()
            assert manager.get(task["id"]).state == "done"
            assert task["id"] not in {m.payload["task_id"] for m in orders}
            history = [h["event"] for h in await srv.app.state.store.history(task["id"])]
            assert "requeued" not in history and history[-1] == "done"


async def test_a_task_is_in_the_database_before_its_201(tmp_path: Path) -> None:
    """A lone server killed right after answering 201 lost the task (the fault soak: "task
    vanished, 404 after it was acknowledged"): the answer waits for the write. The writes
    are held here until the request itself waits for one."""
    settings = server_settings(tmp_path)
    staff = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
    async with (
        running_server(settings) as srv,
        httpx.AsyncClient(base_url=srv.url, headers=staff) as http,
    ):
        store = srv.app.state.store
        real_flush = store.flush
        gate, asked = asyncio.Event(), asyncio.Event()

        async def held_flush() -> None:
            task = asyncio.current_task()
            if task is not None and task.get_name() != "db-writer":
                asked.set()  # the request waits for the write
            await gate.wait()
            await real_flush()

        store.flush = held_flush
        body = {"kind": "go_to_poi", "params": {"poi": "sword"}}
        post = asyncio.create_task(http.post("/api/tasks", json=body))
        waits = asyncio.create_task(asked.wait())
        done, _ = await asyncio.wait({post, waits}, return_when=asyncio.FIRST_COMPLETED)
        assert post not in done, "answered 201 before the task was written"
        gate.set()
        reply = await post
        assert reply.status_code == 201, reply.text
        stored = await store.task(reply.json()["id"])
        assert stored is not None and stored.params["poi"] == "sword"
