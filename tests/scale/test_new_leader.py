"""A process that has just won the leadership handles a robot's must-arrive message once
(docs/protocol.md, "Delivery guarantee"; docs/scaling.md).

Its deciding components start one after the other (the Traffic Manager before the database's
task store is loaded, say): for that while it leads but does not serve, and acknowledges
nothing. A robot's request that came then was handed to the components already up, which
granted it, and left unacknowledged; the robot's link sent it again, and once serving the new
leader handled the copy a second time (a second grant of the corridor in the event log, seen
three times in tests/scale/test_tour_across.py[follower]). Now a must-arrive message is not
published while the components start: the copy sent again is handled once, when they are all
up, and acknowledged.

Real PostgreSQL (the leadership), a real redis-server (the broker), the real cluster wiring
(backend/cluster.py), the real hub and a robot over a real WebSocket; the deciding component
is a stand-in that counts what it handles, behind the real fenced endpoint, and a second
stand-in holds the start-up open until the test lets it finish."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

import orjson
import pytest
from fastapi import FastAPI

import backend.app
from backend.auth import Role
from backend.fencing import deciding_endpoint
from backend.settings import Settings, StaticToken
from backend.testing import running_server
from bench.servers import wait_until
from guidebot.messages import Message
from tests.hub.test_security import raw_socket, receive
from tests.server.postgres import PostgresServer

from .redis import RedisServer

ROBOT = StaticToken(token="token-robot-R1-new-leader", name="R1", role=Role.ROBOT)


async def _true(value: object) -> object:
    return value


@pytest.mark.parametrize("linked_to", ["leader", "follower"])
async def test_a_request_that_comes_while_the_new_leader_starts_is_handled_once(
    postgres: PostgresServer,
    redis: RedisServer,
    monkeypatch: pytest.MonkeyPatch,
    linked_to: str,
) -> None:
    """The robot on the new leader itself, or on a follower (its request comes through the
    broker)."""
    handled: list[Message] = []
    up = asyncio.Event()
    finish_start = asyncio.Event()

    @contextlib.asynccontextmanager
    async def traffic(app: FastAPI) -> AsyncIterator[None]:
        endpoint = deciding_endpoint(app, "traffic_manager")
        endpoint.subscribe("request_area", handled.append)
        up.set()
        yield
        endpoint.close()

    @contextlib.asynccontextmanager
    async def slow_to_start(_app: FastAPI) -> AsyncIterator[None]:
        await finish_start.wait()
        yield

    monkeypatch.setattr(backend.app, "COMPONENTS", [traffic, slow_to_start])
    database = postgres.database()

    def settings(process: str) -> Settings:
        return Settings(
            db_url=database,
            broker_url=redis.url,
            tokens=[ROBOT],
            # No fail-over here: alpha keeps its lease while beta starts in the same event loop
            # (a 2 s lease could lapse on a loaded machine and make beta the leader).
            leader_poll_s=0.5,
            leader_lease_s=60.0,
            process_name=process,
        )

    async with contextlib.AsyncExitStack() as servers:
        server = await servers.enter_async_context(running_server(settings("alpha")))
        leadership = server.app.state.leadership
        await asyncio.wait_for(up.wait(), 30)  # it leads; one component is up, one starts
        assert leadership.leading and not leadership.serving
        if linked_to == "follower":
            follower = await servers.enter_async_context(running_server(settings("beta")))
            await wait_until(
                lambda: _true(
                    server.app.state.broker.connected and follower.app.state.broker.connected
                ),
                30,
                "both processes on the broker",
            )
        ws_url = server.ws_url if linked_to == "leader" else follower.ws_url
        marks: list[str] = []
        server.app.state.hub.endpoint("observer").subscribe(
            "say", lambda m: marks.append(m.payload["text"])
        )
        try:
            async with raw_socket(ws_url, ROBOT.token) as robot:
                assert (await receive(robot))["type"] == "welcome"
                request = {
                    "type": "request_area",
                    "id": "ask-1",
                    "payload": {"robot": "R1", "area": "corridor"},
                }
                acks: list[str] = []

                async def send(mark: str, *, copy: bool = True) -> None:
                    """A copy of the request, then a mark behind it: once the mark has reached the
                    leader (through the broker from a follower, in order), so has the
                    request. Acks read meanwhile are kept."""
                    if copy:
                        await robot.send(orjson.dumps(request).decode())
                    say = {"type": "say", "payload": {"text": mark}}
                    await robot.send(orjson.dumps(say).decode())
                    await wait_until(lambda: _true(mark in marks), 30, f"{mark} on the leader")
                    ping = {"type": "ping", "id": mark}
                    await robot.send(orjson.dumps(ping).decode())
                    while (frame := await receive(robot)).get("correlation_id") != mark:
                        if frame["type"] == "ack":
                            acks.append(frame["payload"]["message_id"])

                await send("during-start")
                assert handled == [], "a component handled it before the leader served"
                finish_start.set()
                await wait_until(lambda: _true(leadership.serving), 30, "the leader to serve")
                await send("serving")  # the robot's link sends it again: no ack came
                await wait_until(lambda: _true(handled), 30, "the copy handled")
                while not acks:  # from a follower the ack comes back through the broker
                    frame = await receive(robot)
                    if frame["type"] == "ack":
                        acks.append(frame["payload"]["message_id"])
                await send("after", copy=False)
                assert [m.id for m in handled] == ["ask-1"]
                assert acks == ["ask-1"]
        finally:
            finish_start.set()  # else the server's shutdown waits for the start-up
