"""Hostile input on the hub: forbidden types, floods, oversized frames, clients that never read.
Each is refused clearly, the connection that sent it stays usable, and the others see nothing
of it."""

from __future__ import annotations

import asyncio
from typing import Any

import orjson
import pytest
from websockets.asyncio.client import ClientConnection
from websockets.exceptions import ConnectionClosed

from backend.actions import REST_ONLY, RULES
from backend.testing import RunningServer, running_server
from guidebot.client import HubClient, HubError
from guidebot.messages import known_types

from .conftest import TOKENS, ClientFactory, hub_settings, never_reading_client
from .test_routing import Inbox
from .test_security import authenticated, receive, still_up

WAIT = 15.0


async def collect(ws: ClientConnection) -> list[dict[str, Any]]:
    """Everything received up to the pong of the ping with id ``alive`` (frames may be
    batches)."""
    seen: list[dict[str, Any]] = []
    while True:
        data = orjson.loads(await asyncio.wait_for(ws.recv(), WAIT))
        for message in data if isinstance(data, list) else [data]:
            if message["type"] == "pong" and message["correlation_id"] == "alive":
                return seen
            seen.append(message)


async def until_pong(ws: ClientConnection) -> list[dict[str, Any]]:
    """Everything received before the pong of a ping sent now."""
    await ws.send(orjson.dumps({"type": "ping", "id": "alive"}).decode())
    return await collect(ws)


def test_the_permission_table_names_only_registered_types() -> None:
    assert set(RULES) - REST_ONLY <= known_types(), sorted(set(RULES) - REST_ONLY - known_types())


@pytest.mark.parametrize("who", ["panel", "gui", "R1", "op"])
@pytest.mark.parametrize(
    ("type_", "payload"),
    [
        ("area_granted", {"robot": "R2", "area": "corridor"}),
        ("task_assigned", {"task_id": "t1", "robot": "R2", "net": "give_tour"}),
        ("door_opened", {"door": "front"}),
    ],
)
async def test_authority_messages_are_refused_from_clients(
    server: RunningServer, connect: ClientFactory, who: str, type_: str, payload: dict[str, str]
) -> None:
    victim = await connect("R2")
    inbox = Inbox()
    victim.subscribe(type_, inbox)
    await victim.sync()
    async for ws in authenticated(server, who):
        frame = {"type": type_, "id": "forged", "destination": "R2", "payload": payload}
        await ws.send(orjson.dumps(frame).decode())
        error = await receive(ws)
        assert error["payload"]["code"] == "forbidden_type"
        assert error["payload"]["message_id"] == "forged"
        assert f"may not publish {type_!r}" in error["payload"]["reason"]
        await still_up(ws)
    await victim.sync()
    assert inbox.queue.empty()


async def test_panels_and_displays_publish_nothing_but_control_messages(
    connect: ClientFactory,
) -> None:
    panel = await connect("panel")
    with pytest.raises(HubError) as refused:
        await panel.request("get_path", {"robot": "R1", "to_node": "x"}, timeout=WAIT)
    assert refused.value.code == "forbidden_type"
    await panel.sync()  # ping still answered


async def test_robot_task_requests_are_rate_limited_on_the_hub(listener: str) -> None:
    settings = hub_settings(listener, task_requests_per_minute=1.0, task_request_burst=2)
    async with running_server(settings) as server:
        async for ws in authenticated(server, "R1"):
            for i in range(3):
                frame = {"type": "task_request", "id": f"t{i}", "payload": {"kind": "tour"}}
                await ws.send(orjson.dumps(frame).decode())
            answers = await until_pong(ws)
            refused = [
                (m["payload"]["code"], m["payload"]["message_id"])
                for m in answers
                if m["type"] == "error"
            ]
            assert refused == [("rate_limited", "t2")]
            # A task_request is acknowledged by its answer (the Task Manager's), not by the hub.
            assert not [m for m in answers if m["type"] == "ack"]


async def test_oversized_and_mixed_frames_are_refused_per_message(server: RunningServer) -> None:
    async for ws in authenticated(server, "R1"):
        await ws.send("[" + " " * (2 << 20) + "]")  # 2 MiB: over hub_max_message_bytes
        assert [m["payload"]["code"] for m in await until_pong(ws)] == ["too_large"]
        mixed = [
            {"type": 5},
            "text",
            {"type": "robot_state", "id": "ok", "payload": {"robot": "R1"}},
            {"type": "robot_state", "id": "bad", "payload": {"robot": "R1", "x": "far"}},
            {"type": "no_such_type", "id": "u"},
        ]
        await ws.send(orjson.dumps(mixed).decode())
        codes = [m["payload"]["code"] for m in await until_pong(ws)]
        assert codes == ["invalid_envelope", "malformed_message", "invalid_payload", "unknown_type"]


async def flooding(ws: ClientConnection, frame: str, times: int) -> None:
    for _ in range(times):
        await ws.send(frame)


async def test_one_client_flooding_garbage_does_not_stall_the_others(
    server: RunningServer, connect: ClientFactory
) -> None:
    """The flood is read in turn with everything else, one frame at a time: the others' round
    trips are answered between its frames. Counted on the hub (in this process), not timed:
    had the hub handled the flood in one go (it held the loop for about a second), no round
    trip could begin and end while the flood was half refused."""
    hub = server.app.state.hub
    gui = await connect("gui")
    await gui.sync()
    async for ws in authenticated(server, "R1"):
        before = hub.refused
        flood = orjson.dumps([{"type": "teleport", "id": str(i)} for i in range(200)]).decode()
        sender = asyncio.create_task(flooding(ws, flood, 100))  # 20 000 refused messages
        reader = asyncio.create_task(collect(ws))
        between = 0  # gui round trips begun and answered while the flood was being refused
        while (begun := hub.refused - before) < 20_000:
            await asyncio.wait_for(gui.sync(), WAIT)
            if 0 < begun and hub.refused - before < 20_000:
                between += 1
        await sender
        await ws.send(orjson.dumps({"type": "ping", "id": "alive"}).decode())
        errors = await reader
        assert len(errors) == 20_000 and {m["payload"]["code"] for m in errors} == {"unknown_type"}
    assert between >= 3


async def test_a_client_that_never_reads_is_dropped_after_the_send_timeout(
    listener: str,
) -> None:
    settings = hub_settings(listener, hub_send_timeout_s=1.0)
    async with running_server(settings) as server:
        silent = await never_reading_client(server, TOKENS["op"].token)
        await silent.send(orjson.dumps({"type": "subscribe", "payload": {"patterns": ["say"]}}))
        hub = server.app.state.hub
        async with HubClient(server.hub_url, TOKENS["R1"].token) as r1:
            await r1.sync()
            text = "x" * 65536
            for i in range(150):  # 10 MB, far below the 4096-message queue bound
                r1.publish("say", {"text": f"{i}:{text}"})
            await r1.sync()
            await asyncio.wait_for(hub.clients["ann"].closing.wait(), WAIT)
            assert "ann" not in hub.clients
            assert hub.overflow_disconnects == 1
            await r1.sync()  # the hub goes on
        with pytest.raises(ConnectionClosed):
            while True:
                await asyncio.wait_for(silent.recv(), WAIT)
