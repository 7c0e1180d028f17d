"""The hub turns a client's payload into its model once, at the edge: an in-process module
subscribed by model gets that object, and a payload the hub refused never reaches it."""

from __future__ import annotations

from backend.testing import RunningServer
from guidebot.client import HubError
from guidebot.messages import Message
from guidebot.payloads.robot import RobotState

from .conftest import ClientFactory

WAIT = 10.0


async def test_a_module_gets_the_model_the_hub_validated(
    server: RunningServer, connect: ClientFactory
) -> None:
    hub = server.app.state.hub
    module = hub.endpoint("watcher")
    typed: list[tuple[Message, RobotState]] = []
    already: list[object] = []
    module.subscribe("robot_state", lambda m: already.append(m.typed_or_none()))
    module.on(RobotState, lambda m, state: typed.append((m, state)))
    r1 = await connect("R1")
    r1.publish("robot_state", {"robot": "R1", "x": 1.5, "seq": 1})
    r1.publish("robot_state", {"robot": "R1", "x": "far", "seq": 2})  # refused at the edge
    await r1.sync()
    assert [(m.source, s.x, s.seq) for m, s in typed] == [("R1", 1.5, 1)]
    assert already == [typed[0][1]]  # validated by the hub before any handler ran
    assert isinstance(r1.last_error, HubError) and r1.last_error.code == "invalid_payload"
    module.close()
