"""RGM: a net started through the hub runs on the server and talks over the hub."""

from __future__ import annotations

from backend.testing import RunningServer
from guidebot.client import HubClient
from guidebot.messages import Message

from .test_api import eventually


async def test_a_net_requested_on_the_hub_runs_on_the_server(server: RunningServer) -> None:
    async with HubClient(server.ws_url, server.admin_token) as staff:
        moves: list[Message] = []
        ended: list[Message] = []

        def servos_answer(message: Message) -> None:
            # Stands in for a head: confirm every servo the net moves.
            moves.append(message)
            for servo, position in message.payload["servos"].items():
                staff.publish("servo_in_position", {"servo": servo, "position": position})

        staff.subscribe("move_servos", servos_answer)
        staff.subscribe("petri_net_ended", ended.append)
        await staff.sync()
        staff.publish(
            "run_petri_net",
            {"net": "wink_one_eye", "instance_id": "rgm-wink-1", "params": {"hold_s": 0.05}},
        )
        done = await eventually(
            lambda: [m for m in ended if m.payload["instance_id"] == "rgm-wink-1"]
        )
        assert done[0].payload["outcome"] == "done" and done[0].source == "rgm"
        assert moves and moves[0].source == "rgm"
        # A request the server cannot run is refused, with a reason, and nobody waits forever.
        staff.publish("run_petri_net", {"net": "no_such_net", "instance_id": "rgm-bad-1"})
        failed = await eventually(
            lambda: [m for m in ended if m.payload["instance_id"] == "rgm-bad-1"]
        )
        assert failed[0].payload["outcome"] == "failed"
