"""A leader that loses its lease exits its process at once (backend/cluster.py, fencing). A
server run inside another program, as every in-process test server is, must not take that
program with it: under a loaded CI run a test's in-process leader missed its lease and the
pytest worker died ("node down: Not properly terminated"), and pytest-xdist then waited for
ever. There the server stops instead. Real PostgreSQL (the lease) and redis (the broker)."""

from __future__ import annotations

from backend.settings import Settings
from backend.testing import running_server
from bench.servers import wait_until
from tests.server.postgres import PostgresServer

from .redis import RedisServer


async def test_an_in_process_leader_that_loses_its_lease_stops_its_server_not_the_program(
    postgres: PostgresServer, redis: RedisServer
) -> None:
    database = postgres.database()
    settings = Settings(
        db_url=database,
        broker_url=redis.url,
        leader_poll_s=0.2,
        leader_lease_s=2.0,
        process_name="alone",
        building_enabled=False,
    )
    async with running_server(settings) as server:
        leadership = server.app.state.leadership

        async def leads() -> bool:
            return bool(leadership.leading)

        await wait_until(leads, 60, "it to lead")
        leadership.on_lost()  # what its lease check does when another process took the lease

        async def stopped_listening() -> bool:
            # Its own listeners, not a probe of its port: once closed, the kernel may give
            # that port to another test's server (CI: /api/health answered for 30 s).
            return not any(listener.is_serving() for listener in server.server.servers)

        await wait_until(stopped_listening, 30, "the server to stop")
