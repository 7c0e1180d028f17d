"""Migrations ship in the package and build the schema on an empty database."""

from __future__ import annotations

from sqlalchemy import inspect

from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.tasks.model import Task, TaskState


async def test_migrations_build_the_schema_and_the_store_round_trips(db_url: str) -> None:
    engine = make_engine(db_url)
    try:
        await migrate(engine)
        await migrate(engine)  # idempotent: already at head
        async with engine.connect() as conn:
            tables = await conn.run_sync(lambda c: set(inspect(c).get_table_names()))
        assert {"site", "tasks", "task_history", "events", "alembic_version"} <= tables
        store = DbStore(make_sessionmaker(engine))
        await store.start()
        task = Task("t1", "go_to", {"node": "hall"}, 3, "admin", 1)
        store.record(task, "created")
        task.move(TaskState.ASSIGNED)
        task.robot = "R1"
        store.record(task, "assigned")
        await store.stop()
        [loaded] = await store.load_open_tasks()
        assert (loaded.id, loaded.state, loaded.robot) == ("t1", TaskState.ASSIGNED, "R1")
        assert [h["state"] for h in await store.history("t1")] == ["queued", "assigned"]
        assert await store.max_seq() == 1
        assert await store.save_site({"name": "x"}) == 1
        assert await store.save_site({"name": "y"}) == 2
        assert await store.load_site() == (2, {"name": "y"})
    finally:
        await engine.dispose()
