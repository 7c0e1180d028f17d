"""A real robot agent on virtual CAN evacuates when the demo museum's fire alarm input is
raised at the building simulator's control port (issue 35, docs/emergency.md)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import can
import httpx
import pytest

from building_sim.control import serve_control
from guidebot.messages import Message
from guidebot.site.schema import Site
from guidebot.testing import wait_until
from robot_agent.navigation import Navigator
from robot_agent.robocan import protocol as p

from .test_e2e import fleet_up

pytestmark = pytest.mark.timeout(120)

ALARM = "/points/otb_ground/fire_alarm"


def _speed(frame: can.Message) -> int:
    """The wheel speed a SET_VELOCITY frame commands (µm/s)."""
    return int(p.parse_set_velocity(bytes(frame.data))[1] * 1e6)


async def test_alarm_stops_the_robot_sends_it_to_safety_and_resume_runs_its_tour(
    tmp_path: Path, demo_site: Site
) -> None:
    async with fleet_up(tmp_path, demo_site) as fleet, serve_control(fleet.building) as url:
        headers = {"Authorization": f"Bearer {fleet.server.admin_token}"}
        order_of: list[Message] = []  # the on-board bus, in order

        def on_board(message: Message) -> None:
            if message.type not in ("odometry", "sonar_ranges", "petri_net_event"):
                order_of.append(message)

        fleet.agent.bus.endpoint("test-evacuate").subscribe("*", on_board, tap=True)
        task_id = await fleet.request_task("tour", {"tour": "ground", "lang": "es"})
        await fleet.wait_for(lambda: fleet.of("node_reached") or fleet.ended(task_id))
        assert not fleet.ended(task_id), fleet.ended(task_id)[0].payload  # on its way
        async with (
            httpx.AsyncClient(base_url=url) as control,
            httpx.AsyncClient(base_url=fleet.server.url, headers=headers) as http,
        ):
            raised, start = time.time(), len(order_of)
            assert (await control.post(ALARM, json={"value": 1})).status_code == 200

            def reported(state: str) -> list[Message]:
                return [m for m in fleet.of("evacuation_state") if m.payload["state"] == state]

            await fleet.wait_for(lambda: reported("stopped"))
            # The first thing the robot does on the order: a stop command to the base, before
            # its task's net is killed or anything is said ...
            since = order_of[start:]
            types = [m.type for m in since]
            kill = types.index("kill_petri_net")
            last_command = next(m for m in reversed(since[:kill]) if m.type == "set_velocity")
            assert last_command.payload == {"v": 0.0, "w": 0.0}
            assert types.index("say") > kill

            # ... which reaches the wheels on the CAN bus as zero-velocity frames.
            # (The tap reads the bus in its own turn: the frame may come a moment after.)
            def stops_seen() -> list[can.Message]:
                frames = [f for f in fleet.can_tap.velocity_frames() if f.timestamp >= raised]
                return [f for f in frames if _speed(f) == 0]

            try:
                await wait_until(lambda: bool(stops_seen()), timeout=30)
            except TimeoutError:
                raise AssertionError(
                    "no zero-velocity frame on the CAN bus after the alarm"
                ) from None
            stops = stops_seen()
            # The robot says when its stop went out on the bus (guidebot bench emergency).
            [stopped] = reported("stopped")
            assert stopped.payload["stopped_at"] >= stops[0].timestamp
            print(f"alarm_to_stop_ms={(stops[0].timestamp - raised) * 1000:.0f}")
            # It says the words in its visitor's language, and drives to its safe spot.
            said = [m.payload for m in fleet.onboard_of("say")]
            assert any(s["text"].startswith("Alarma de incendio") for s in said), said
            [order] = fleet.of("evacuate")
            # A must-arrive message: the robot's link acknowledged it (else it is sent again).
            await fleet.wait_for(
                lambda: any(m.payload.get("message_id") == order.id for m in fleet.of("ack"))
            )
            await fleet.wait_for(lambda: reported("safe") or len(reported("stuck")) >= 3, 90)
            assert reported("safe"), [m.payload for m in reported("stuck")]
            assert reported("safe")[0].payload["node"] == order.payload["safe_spot"]
            assert not any(m.payload.get("elevator") for m in fleet.of("call_elevator")[-1:])
            assert (await fleet.task(task_id))["state"] == "queued"

            # Resume refused while the input reads alarm; then the building is reset.
            assert (await http.post("/api/emergency/resume")).status_code == 409
            assert (await control.post(ALARM, json={"value": 0})).status_code == 200
            await fleet.wait_for(
                lambda: any(
                    m.payload["state"] == "input_clear" for m in fleet.of("emergency_changed")
                )
            )
            resumed = await http.post("/api/emergency/resume")
            assert resumed.status_code == 200, resumed.text
            assert resumed.json()["resumed_tasks"] == [task_id]
            # The cut-off tour runs again on the same robot (not answered as already ended).
            await fleet.wait_for(
                lambda: (
                    len([m for m in fleet.of("task_started") if m.payload["task_id"] == task_id])
                    >= 2
                ),
                timeout=60,
            )


async def test_a_robot_that_had_just_left_its_safe_spot_goes_back_onto_it(
    tmp_path: Path, demo_site: Site
) -> None:
    """The server's way starts at the last node the robot reached: its safe spot. The robot,
    already on its way out of it, drives back onto it before it says it is safe."""
    async with fleet_up(tmp_path, demo_site) as fleet:
        nav = fleet.agent.navigator
        there = await fleet.request_task("go_to", {"node": "charge_b"})
        await fleet.wait_for(lambda: fleet.ended(there), timeout=60)
        assert nav.node == "charge_b"
        nav.max_speed = 0.05  # 1 m/s of wall time: the alarm comes on the way out
        # Where the base really is: its own odometry (the map pose is re-anchored on the
        # first node of every path, so it would say "at charge_b" anyway).
        spot = base_position(nav)

        def away() -> float:
            here = base_position(nav)
            return math.hypot(here[0] - spot[0], here[1] - spot[1])

        await fleet.request_task("go_to", {"node": "charge_a"})
        await fleet.wait_for(lambda: nav.node == "charge_b" and away() > 0.5, timeout=60)
        headers = {"Authorization": f"Bearer {fleet.server.admin_token}"}
        async with httpx.AsyncClient(base_url=fleet.server.url, headers=headers) as http:
            declared = await http.post("/api/emergency/declare", json={"reason": "drill"})
            assert declared.status_code == 200, declared.text

        def reported(state: str) -> list[Message]:
            return [m for m in fleet.of("evacuation_state") if m.payload["state"] == state]

        await fleet.wait_for(lambda: reported("safe") or len(reported("stuck")) >= 3, 60)
        [order] = fleet.of("evacuate")
        assert order.payload["path"] == ["charge_b"], order.payload
        assert reported("safe"), [m.payload for m in reported("stuck")]
        assert reported("safe")[0].payload["node"] == "charge_b"
        assert nav.node == "charge_b" and away() <= 2 * nav.tolerance_m, away()


def base_position(nav: Navigator) -> tuple[float, float]:
    """The base's odometry (its own frame, which nothing re-anchors)."""
    assert nav._odom is not None
    return nav._odom[0], nav._odom[1]
