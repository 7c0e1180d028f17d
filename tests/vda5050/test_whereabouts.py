"""A cancelled VDA 5050 vehicle keeps the areas it may be inside (its last node's and its next
node's) until its state shows it out of them (docs/vda5050.md, "Areas at a task's end"): the
rule issue 36 gave GuideBot robots (backend/traffic/whereabouts.py). A cancelOrder stops a
vehicle "as soon as possible", on an edge too; its lastNodeId is then the node behind it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from guidebot.payloads.traffic import RequestArea
from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.sim import SimVehicle
from guidebot.vda5050.topics import parse_broker

from .broker import Mosquitto, mosquitto
from .fleet import TIME_SCALE, V1, Fleet, fleet

pytestmark = pytest.mark.timeout(90)

HELD_AT = 7.5
"""On the edge b (x 4) -> c (x 8): inside the corridor's extent (c and d, 1 m wider: 7 to 13)
while its last node, b, is outside the corridor."""


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


class HeldOnTheEdge(SimVehicle):
    """The simulated V1, held at x = 7.5 on its way from b to c (driving, not moving) until
    ``hold`` is False: the cancel always finds it there, however loaded the machine."""

    hold = True

    def _step(self, dt: float) -> None:
        goal = self.order.nodes[0]["nodeId"] if self.order.nodes else None
        if self.hold and goal == "c" and self.speed > 0:
            dt = max(0.0, min(dt, (HELD_AT - self.x) / self.speed))
        super()._step(dt)


def held_vehicle(broker_url: str) -> HeldOnTheEdge:
    return HeldOnTheEdge(
        parse_broker(broker_url),
        V1,
        map_id="ground",
        node="a",
        time_scale=TIME_SCALE,
        state_period_s=0.2,
    )


def v1_states(f: Fleet) -> list[dict[str, Any]]:
    return [m.payload for m in f.of("robot_state") if m.payload["robot"] == "V1"]


async def test_a_vehicle_cancelled_on_the_edge_into_an_area_keeps_it_until_seen_out(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, held_vehicle(broker.url) as sim:
        traffic = f.server.app.state.traffic
        await wait_until(lambda: f.robot("V1").online, 15)
        task = await f.task("go_to", {"node": "e"})
        await wait_until(lambda: sim.last_node == "b" and sim.x >= HELD_AT, 20)
        assert traffic.locks.holder("corridor") == "V1"
        other = f.server.app.state.hub.endpoint("R1")
        other.publish(RequestArea(robot="R1", area="corridor"))
        await wait_until(lambda: traffic.locks.waiting_for("R1") == ("corridor",))

        answer = await f.http.post(f"/api/tasks/{task}/cancel", json={"reason": "test"})
        assert answer.status_code == 200, answer.text
        await wait_on(
            f.changed, lambda: any(m.payload["task_id"] == task for m in f.of("task_ended")), 20
        )
        await wait_until(lambda: not sim.driving and not sim.order.nodes, 10)
        # Stopped on the edge, inside the corridor's extent: several states later (each one a
        # robot_state the Traffic Manager reads), the corridor is still V1's.
        seen = len(v1_states(f))
        await wait_on(f.changed, lambda: len(v1_states(f)) >= seen + 3, 20)
        assert all(s["task_id"] is None and s["node"] == "b" for s in v1_states(f)[-3:])
        assert traffic.locks.holder("corridor") == "V1"
        assert traffic.locks.waiting_for("R1") == ("corridor",)

        sim.x = 4.0  # staff push it back to b: out of the corridor
        await wait_until(lambda: traffic.locks.holder("corridor") == "R1", 15)
        assert "corridor" not in v1_states(f)[-1]["areas"]
        other.close()


async def test_a_vehicle_cancelled_before_an_area_it_was_not_given_leaves_nothing_held(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """The other side of the rule: held at b (the corridor another robot's), cancelled: its
    request goes at once (it never had it), and an area behind it is not kept."""
    async with fleet(tmp_path, broker.url) as f, held_vehicle(broker.url) as sim:
        traffic = f.server.app.state.traffic
        await wait_until(lambda: f.robot("V1").online, 15)
        other = f.server.app.state.hub.endpoint("R1")
        other.publish(RequestArea(robot="R1", area="corridor"))
        await wait_until(lambda: traffic.locks.holder("corridor") == "R1")
        task = await f.task("go_to", {"node": "e"})
        await wait_until(lambda: traffic.locks.waiting_for("V1") == ("corridor",), 20)
        await wait_until(lambda: sim.last_node == "b" and not sim.driving, 20)
        answer = await f.http.post(f"/api/tasks/{task}/cancel", json={"reason": "test"})
        assert answer.status_code == 200, answer.text
        await wait_until(lambda: traffic.locks.waiting_for("V1") is None, 20)
        assert traffic.locks.holder("corridor") == "R1"
        other.close()
