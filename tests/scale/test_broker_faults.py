"""The broker's faults (docs/scaling.md): a Redis restart is survived (the WebSocket clients stay
connected, the bridges resubscribe, acknowledged tasks are kept), and a process with a slow
network link to Redis does not hold the others back (its link stalled: the others hear a
message while it cannot, whatever the machine's load)."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx

from bench.cluster_clients import WsClient
from bench.servers import ADMIN_TOKEN, GUI_TOKEN, ServerProcess, start_servers, wait_until
from tests.server.postgres import PostgresServer

from .redis import RedisServer, redis_server

_texts = itertools.count()


async def _true(value: object) -> object:
    return value


async def _say(speaker: WsClient) -> str:
    """The speaker says something new; its words."""
    text = f"hello {next(_texts)}"
    await speaker.send("say", {"text": text})
    return text


def _has(listener: WsClient, text: str) -> bool:
    return any(m["payload"]["text"] == text for m in listener.of_type("say"))


async def _heard(listener: WsClient, text: str, timeout: float = 20) -> None:
    await wait_until(lambda: _true(_has(listener, text)), timeout, f"{text!r}", interval=0.02)


async def _said(speaker: WsClient, listeners: list[WsClient]) -> None:
    """The speaker says something new; until each listener has it."""
    text = await _say(speaker)
    for listener in listeners:
        await _heard(listener, text)


async def _listener(server: ServerProcess) -> WsClient:
    gui = await WsClient.connect(server, GUI_TOKEN)
    await gui.send("subscribe", {"patterns": ["say"]})
    await gui.send("ping", {}, id="subscribed")
    await wait_until(lambda: _true(gui.of_type("pong")), 20, "pong")
    return gui


async def _broker_connected(server: ServerProcess, connected: bool) -> bool:
    health = await server.health()
    return bool(health and health["cluster"]["broker"]["connected"] is connected)


async def test_a_redis_restart_is_survived(postgres: PostgresServer, tmp_path: Path) -> None:
    with redis_server() as redis:
        async with start_servers(["alpha", "beta"], postgres.database(), redis.url, tmp_path) as (
            alpha,
            beta,
        ):
            await _redis_restart(redis, alpha, beta)


async def _redis_restart(redis: RedisServer, alpha: ServerProcess, beta: ServerProcess) -> None:
    await alpha.until(alpha.leads, "alpha to lead")
    gui = await _listener(alpha)
    local_robot = await WsClient.connect(alpha, "robot-R2-demo-token")
    robot = await WsClient.connect(beta, "robot-R1-demo-token")
    try:
        await _said(robot, [gui])  # across processes, through Redis
        redis.stop()
        await wait_until(lambda: _broker_connected(beta, False), 20, "beta to see Redis gone")
        # Without the broker each process still serves its own clients ...
        await _said(local_robot, [gui])
        # ... and what the server acknowledges is kept: a task created now is in the database.
        async with httpx.AsyncClient(headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}) as http:
            created = await http.post(
                f"{alpha.url}/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}}
            )
            assert created.status_code in (200, 201), created.text
            redis.start()
            for server in (alpha, beta):
                await wait_until(lambda s=server: _broker_connected(s, True), 30, "resubscribed")
            await _said(robot, [gui])  # the same WebSocket connections: nobody reconnected
            listed = await http.get(f"{alpha.url}/api/tasks", params={"limit": 1000})
        assert created.json()["id"] in {t["id"] for t in listed.json()["tasks"]}
        assert gui.ws.close_code is None and robot.ws.close_code is None
    finally:
        for client in (gui, local_robot, robot):
            await client.close()


@contextlib.asynccontextmanager
async def _stalling_link(port: int) -> AsyncIterator[tuple[int, asyncio.Event]]:
    """A TCP proxy to 127.0.0.1:``port`` that passes every chunk on, each way, only while the
    event it yields is set (cleared: a network link that stalls); yields its own port too."""
    moving = asyncio.Event()
    moving.set()

    async def pump(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        queue: asyncio.Queue[bytes] = asyncio.Queue()

        async def later() -> None:
            while True:
                data = await queue.get()
                await moving.wait()
                if not data:
                    break
                writer.write(data)
                await writer.drain()
            writer.close()

        sender = asyncio.create_task(later())
        with contextlib.suppress(ConnectionError):
            while data := await reader.read(65536):
                queue.put_nowait(data)
        queue.put_nowait(b"")
        with contextlib.suppress(ConnectionError):
            await sender

    links: set[asyncio.Future[Any]] = set()

    async def handle(client_r: asyncio.StreamReader, client_w: asyncio.StreamWriter) -> None:
        up_r, up_w = await asyncio.open_connection("127.0.0.1", port)
        link = asyncio.gather(pump(client_r, up_w), pump(up_r, client_w), return_exceptions=True)
        links.add(link)
        try:
            with contextlib.suppress(asyncio.CancelledError):
                await link
        finally:
            for writer in (client_w, up_w):
                writer.close()
                with contextlib.suppress(ConnectionError, asyncio.CancelledError):
                    await writer.wait_closed()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    try:
        yield int(server.sockets[0].getsockname()[1]), moving
    finally:
        server.close()
        for link in links:
            link.cancel()
        await asyncio.gather(*links, return_exceptions=True)
        await asyncio.sleep(0.1)  # the handlers close their sockets


async def test_a_slow_process_does_not_hold_the_others_back(
    redis: RedisServer, postgres: PostgresServer, tmp_path: Path
) -> None:
    db = postgres.database()
    async with (
        start_servers(["alpha", "beta"], db, redis.url, tmp_path) as (alpha, beta),
        _stalling_link(redis.port) as (slow_port, moving),
    ):
        slow_url = f"redis://127.0.0.1:{slow_port}/0"
        gamma = ServerProcess("gamma", db, slow_url, tmp_path / "gamma.log")
        try:
            await gamma.until(gamma.ready, "gamma to join through its slow link")
            await alpha.until(alpha.leads, "alpha to lead")
            robot = await WsClient.connect(alpha, "robot-R1-demo-token")
            fast, slow = await _listener(beta), await _listener(gamma)
            try:
                await _said(robot, [fast, slow])  # everyone is subscribed everywhere
                for _ in range(3):
                    moving.clear()  # gamma's link to Redis stalls
                    text = await _say(robot)
                    await _heard(fast, text)  # beta does not wait for gamma
                    assert not _has(slow, text), "gamma heard it through a stalled link"
                    moving.set()
                    await _heard(slow, text)  # gamma gets it once its own link moves
            finally:
                moving.set()
                for client in (robot, fast, slow):
                    await client.close()
        finally:
            gamma.stop()
