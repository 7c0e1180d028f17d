"""Shared by the scale-out tests: one private PostgreSQL and one private redis-server for the
session, and a pair of real server processes on them for each test that asks."""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest

from bench.servers import ServerProcess, start_servers
from tests.server.postgres import PostgresServer, postgres_server

from .redis import RedisServer, redis_server


@pytest.fixture(scope="session")
def redis() -> Iterator[RedisServer]:
    with redis_server() as server:
        yield server


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    with postgres_server() as pg:
        yield pg


@pytest.fixture
async def pair(
    redis: RedisServer, postgres: PostgresServer, tmp_path: Path
) -> AsyncIterator[list[ServerProcess]]:
    """alpha (started first: it leads) and beta (follows), on an empty database."""
    async with start_servers(["alpha", "beta"], postgres.database(), redis.url, tmp_path) as pair:
        yield pair
