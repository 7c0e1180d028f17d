"""A task's end never releases an area the robot may still be inside while it moves (docs/
server.md, "Lock policy"; issue 36: in the fault soak a charge preempted by a tour lost its
corridor while the robot drove through it, and another robot was granted it). Real server,
real hub clients speaking as robots."""

from __future__ import annotations

from typing import Any

from backend.testing import RunningServer

from .conftest import PANEL_TOKEN
from .test_api import GROUND, Http, HubRobot, eventually, robot

SWORD: dict[str, Any] = {"kind": "go_to_poi", "params": {"poi": "sword"}}
"""A visit to gb1, through the corridor from the west."""


def report(bot: HubRobot, node: str, *, areas: list[str], mode: str = "busy") -> None:
    """robot_state as an agent sends it: where it is, its task, what it holds."""
    bot.node = node
    payload = {"robot": bot.name, "node": node, "mode": mode, "task_id": bot.task_id}
    bot.client.publish("robot_state", {**payload, "areas": areas})


def reached(bot: HubRobot, node: str) -> None:
    """node_reached: the robot's word on each node, between its robot_state reports."""
    bot.client.publish("node_reached", {"robot": bot.name, "node": node, "floor": "F0"})


async def start(bot: HubRobot, task: dict[str, Any] | str) -> str:
    task_id = task if isinstance(task, str) else str(task["task_id"])
    bot.task_id = task_id
    bot.client.publish("task_started", {"task_id": task_id, "robot": bot.name})
    await bot.client.sync()
    return task_id


async def end(bot: HubRobot, outcome: str) -> None:
    assert bot.task_id is not None
    payload = {"task_id": bot.task_id, "robot": bot.name, "outcome": outcome}
    bot.client.publish("task_ended", payload)
    bot.task_id = None
    await bot.client.sync()


async def holds_corridor(bot: HubRobot, via: str, to: str) -> None:
    """The robot's path (asked of the Traffic Manager) and its grant of the corridor."""
    ask = {"robot": bot.name, "from_node": via, "to_node": to}
    path = await bot.client.request("get_path", ask)
    assert "corridor_w" in path.payload["nodes"]
    grant = await bot.client.request("request_area", {"robot": bot.name, "area": "corridor"})
    assert grant.type == "area_granted"


async def test_a_preempted_charge_keeps_the_corridor_the_robot_drives_into_until_it_stops(
    server: RunningServer, http: Http
) -> None:
    """R1 drives from gb1 into the corridor on its way to charge when a visitor's tour
    preempts the charge: the server ends the charge at once, but R1 drives on until the
    cancel reaches it. The corridor stays R1's until R1's own word shows it out."""
    traffic = server.app.state.traffic
    panel = http(PANEL_TOKEN)
    async with robot(server, "R1", "gb1") as r1:
        charge = await r1.next_order("battery_charge")
        await start(r1, charge.payload)
        await holds_corridor(r1, "gb1", "charge_a")
        report(r1, "gb1", areas=["corridor"])  # on the edge gb1 -> corridor_e
        tour = (await panel.post("/api/tasks", json=GROUND)).json()
        order = await r1.next_order("give_tour")
        assert order.payload["task_id"] == tour["id"]
        async with robot(server, "R2", "ga1") as r2:
            r2.client.publish("request_area", {"robot": "R2", "area": "corridor"})
            await eventually(lambda: traffic.locks.waiting_for("R2") == ("corridor",))
            assert traffic.locks.holder("corridor") == "R1"
            # Still on its way (the cancel not seen yet): in, through, and a report of it.
            reached(r1, "corridor_e")
            report(r1, "corridor_e", areas=["corridor"])
            await r1.client.sync()
            assert traffic.locks.holder("corridor") == "R1"
            # The cancel reaches it: it stops inside and says the charge is over.
            await end(r1, "cancelled")
            assert traffic.locks.holder("corridor") == "R1"
            await start(r1, tour["id"])  # the tour, west through the corridor
            await holds_corridor(r1, "corridor_e", "hall")
            for node in ("corridor_w", "ga1"):
                reached(r1, node)
            report(r1, "ga1", areas=[])  # out, and it let the corridor go
            await eventually(lambda: traffic.locks.holder("corridor") == "R2")
            assert not server.app.state.traffic.alerts.is_active("area_conflict", "R2")


async def test_a_task_ending_between_two_state_reports_keeps_the_area_the_robot_reached(
    server: RunningServer, http: Http
) -> None:
    """R1's last robot_state says ga1, but it has since reached corridor_w (node_reached)
    when its task fails: the corridor it stands in is kept, released when it is out."""
    traffic = server.app.state.traffic
    panel = http(PANEL_TOKEN)
    async with robot(server, "R1", "ga1") as r1:
        visit = (await panel.post("/api/tasks", json=SWORD)).json()
        order = await r1.next_order("go_to_poi")
        assert order.payload["task_id"] == visit["id"]
        await start(r1, visit["id"])
        await holds_corridor(r1, "ga1", "gb1")
        report(r1, "ga1", areas=["corridor"])
        reached(r1, "corridor_w")
        await end(r1, "failed")
        async with robot(server, "R2", "ga2") as r2:
            r2.client.publish("request_area", {"robot": "R2", "area": "corridor"})
            await eventually(lambda: traffic.locks.waiting_for("R2") == ("corridor",))
            assert traffic.locks.holder("corridor") == "R1"
            report(r1, "corridor_w", areas=["corridor"], mode="idle")
            await r1.client.sync()
            assert traffic.locks.holder("corridor") == "R1"
            report(r1, "gb1", areas=[], mode="idle")
            await eventually(lambda: traffic.locks.holder("corridor") == "R2")


async def test_a_task_ending_on_the_edge_into_an_area_keeps_it_until_the_robot_stands(
    server: RunningServer, http: Http
) -> None:
    """R1 left ga1 for corridor_w (its next node) when its task ended: it may be on the edge,
    inside the corridor. Kept until its next report shows it standing outside."""
    traffic = server.app.state.traffic
    panel = http(PANEL_TOKEN)
    async with robot(server, "R1", "ga1") as r1:
        visit = (await panel.post("/api/tasks", json=SWORD)).json()
        await r1.next_order("go_to_poi")
        await start(r1, visit["id"])
        await holds_corridor(r1, "ga1", "gb1")
        reached(r1, "ga1")
        await end(r1, "failed")
        assert traffic.locks.holder("corridor") == "R1"
        async with robot(server, "R2", "ga2") as r2:
            r2.client.publish("request_area", {"robot": "R2", "area": "corridor"})
            await eventually(lambda: traffic.locks.waiting_for("R2") == ("corridor",))
            assert traffic.locks.holder("corridor") == "R1"
            report(r1, "ga1", areas=[], mode="idle")  # standing at ga1, no task: outside
            await eventually(lambda: traffic.locks.holder("corridor") == "R2")
