"""Policy out of the transport: a client's message passes an ordered list of inbound checks
(backend/hub/checks.py), the hub's publish permissions first, then what the server's parts
register (the task_request rate limit, backend/tasks/inbound.py). The order is the one clients
see (docs/protocol.md, "Refusals"): a message refused by an earlier check never reaches a later
one, so an impersonating task_request is refused ``impersonation`` and not charged."""

from __future__ import annotations

from typing import Any

import orjson

from backend.hub.checks import Stage
from backend.hub.core import RemoteClient
from backend.testing import RunningServer, running_server
from guidebot.messages import Message

from .conftest import hub_settings
from .test_hostile import until_pong
from .test_security import authenticated


def frame(id_: str, type_: str = "task_request", **fields: Any) -> str:
    message = {"type": type_, "id": id_, "payload": {"kind": "tour"}, **fields}
    return orjson.dumps(message).decode()


def refusals(answers: list[dict[str, Any]]) -> list[tuple[str, str]]:
    return [
        (m["payload"]["code"], m["payload"]["message_id"]) for m in answers if m["type"] == "error"
    ]


async def test_the_checks_run_in_the_documented_order(server: RunningServer) -> None:
    checks = server.app.state.hub.checks
    hub_own = ["forbidden_type", "source_is_sender", "payload_allowed"]
    assert checks.order("task_request") == [*hub_own, "task_request_rate"]
    assert checks.order("robot_state") == hub_own


async def test_an_impersonating_task_request_is_refused_before_the_rate_limit(
    listener: str,
) -> None:
    settings = hub_settings(listener, task_requests_per_minute=1.0, task_request_burst=1)
    async with running_server(settings) as server:
        async for ws in authenticated(server, "R1"):
            await ws.send(frame("as-r2", source="R2"))
            await ws.send(frame("for-x", payload={"kind": "tour", "requester": "x"}))
            await ws.send(frame("bad", payload={"kind": "tour", "priority": True}))
            await ws.send(frame("first"))  # the burst of one: neither refusal was charged
            await ws.send(frame("second"))
            await ws.send(frame("first"))  # a copy sent again: not charged, not refused
            assert refusals(await until_pong(ws)) == [
                ("impersonation", "as-r2"),
                ("impersonation", "for-x"),
                ("invalid_payload", "bad"),
                ("rate_limited", "second"),
            ]


async def test_a_part_of_the_server_registers_its_own_check(server: RunningServer) -> None:
    hub = server.app.state.hub
    seen: list[Message] = []
    module = hub.endpoint("watcher")
    module.subscribe("robot_state", seen.append)

    def no_far_robots(client: RemoteClient, type_: str, message: Message | None) -> Any:
        assert message is not None and message.source == client.name  # routable: stamped
        return ("forbidden_request", "too far") if message.payload.get("x", 0) > 100 else None

    remove = hub.checks.add("far", Stage.ROUTED, no_far_robots, types=["robot_state"])
    async for ws in authenticated(server, "R1"):
        state = {"robot": "R1", "seq": 1}
        await ws.send(frame("near", "robot_state", payload={**state, "x": 1.0}))
        await ws.send(frame("far", "robot_state", payload={**state, "x": 500.0}))
        await ws.send(frame("wrong", "robot_state", payload={**state, "x": "far"}))
        await ws.send(frame("other", "robot_state", payload={**state, "robot": "R2"}))
        assert refusals(await until_pong(ws)) == [
            ("forbidden_request", "far"),
            ("invalid_payload", "wrong"),
            ("impersonation", "other"),
        ]
        remove()
        await ws.send(frame("far again", "robot_state", payload={**state, "x": 500.0}))
        assert refusals(await until_pong(ws)) == []
    assert [m.id for m in seen] == ["near", "far again"]
    module.close()
