"""The fleet's safety invariants (guidebot.invariants) over a whole run of several robots
through doors, two elevators and back-to-back corridors: checked live on the hub and again
on the server's event log (GET /api/events), as the soak benchmark does."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import httpx
import pytest

from guidebot.invariants import InvariantChecker
from guidebot.messages import Message
from tests.robot.safety_rig import fleet, safety_site

pytestmark = pytest.mark.timeout(90)


async def _events(url: str, token: str) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    after = 0
    async with httpx.AsyncClient(base_url=url) as http:
        while True:
            r = await http.get(
                "/api/events",
                params={"after_id": after, "limit": 500},
                headers={"Authorization": f"Bearer {token}"},
            )
            assert r.status_code == 200, r.text
            page = r.json()
            out += page["events"]
            if not page["events"]:
                return out
            after = page["next_after_id"]


async def test_several_robots_never_break_the_safety_invariants(tmp_path: Path) -> None:
    routes = {
        "R1": ["up_w", "up_e", "home1"],  # lift_a up, door D1, back down
        "R2": ["east", "home2"],  # door D0, corr_a + corr_b, and back
        "R3": ["up_e", "w_dock"],  # corr_a + corr_b, lift_b, and back
    }
    async with fleet(tmp_path, list(routes), start={"R3": "w_dock"}) as f:

        async def run(robot: str) -> None:
            for node in routes[robot]:
                await f.go(robot, node, timeout=60)

        await asyncio.gather(*(run(robot) for robot in routes))
        await f.wait_for(lambda: all(d.state == "closed" for d in f.building.doors.values()))
        live = f.checker
        assert not live.violations, [str(v) for v in live.violations]
        reached = {m.payload["node"] for m in f.of("node_reached")}
        assert {"door0", "door1", "la0", "la1", "lb0", "lb1", "ca2", "cb1"} <= reached
        assert live.counts["door"] >= 4 and live.counts["cabin"] >= 6, live.counts
        assert live.counts["area"] >= 10, live.counts
        # The same run, replayed from the server's event log.
        replay = InvariantChecker.from_site(f.server.app.state.sites.site)
        replay.feed_events(await _events(f.server.url, f.server.admin_token))
        assert not replay.violations, [str(v) for v in replay.violations]
        assert replay.counts["door"] == live.counts["door"]
        assert replay.counts["cabin"] == live.counts["cabin"]


def _msg(type_: str, **payload: Any) -> Message:
    return Message(type=type_, source="test", payload=payload)


def test_the_checker_catches_each_kind_of_violation() -> None:
    from guidebot.site.validate import validate_site

    checker = InvariantChecker.from_site(validate_site(safety_site()))
    feed = checker.feed_message
    feed(_msg("door_closed", door="D0"))
    feed(_msg("node_reached", robot="R1", node="door0", floor="F0"))
    # A reply to one requester is not the door's state.
    feed(Message(type="door_opened", source="b", destination="R2", payload={"door": "D0"}))
    feed(_msg("node_reached", robot="R2", node="door0", floor="F0"))
    feed(_msg("elevator_in_position", elevator="lift_a", floor="F1", door_open=True))
    feed(_msg("node_reached", robot="R3", node="la0", floor="F0"))
    feed(_msg("node_reached", robot="R1", node="ca1", floor="F0"))
    feed(_msg("node_reached", robot="R2", node="ca2", floor="F0"))
    feed(_msg("area_granted", robot="R1", area="corr_b"))
    feed(_msg("area_granted", robot="R2", area="corr_b"))
    assert [(v.invariant, v.robot) for v in checker.violations] == [
        ("door", "R1"),
        ("door", "R2"),
        ("cabin", "R3"),
        ("area", "R2"),
        ("area", "R2"),
    ]
    assert "while lift_a was open at F1" in str(checker.violations[2])
    # And the legal sequence is clean.
    clean = InvariantChecker.from_site(validate_site(safety_site()))
    for message in (
        _msg("door_opened", door="D0"),
        _msg("node_reached", robot="R1", node="door0"),
        _msg("elevator_in_position", elevator="lift_a", floor="F0", door_open=True),
        _msg("node_reached", robot="R1", node="la0"),
        _msg("area_granted", robot="R1", area="corr_a"),
        _msg("release_area", robot="R1", area="corr_a"),
        _msg("area_granted", robot="R2", area="corr_a"),
    ):
        clean.feed_message(message)
    assert clean.violations == [] and clean.counts["door"] == 1 and clean.counts["cabin"] == 1


def test_a_door_not_sensed_is_not_judged_closed() -> None:
    """door_closed with sensed false (its module offline) means "unknown", not "closed": the
    door may stand open. Once the sensor reads it closed again, a robot on it is a violation."""
    from guidebot.site.validate import validate_site

    checker = InvariantChecker.from_site(validate_site(safety_site()))
    feed = checker.feed
    feed("door_opened", {"door": "D0"}, 100.0)
    feed("door_closed", {"door": "D0", "sensed": False}, 101.0)
    feed("node_reached", {"robot": "R1", "node": "door0", "at": 101.5}, 101.5)
    assert checker.violations == []
    feed("door_closed", {"door": "D0"}, 110.0)
    feed("node_reached", {"robot": "R2", "node": "door0", "at": 111.0}, 111.0)
    assert [(v.invariant, v.robot) for v in checker.violations] == [("door", "R2")]
    assert checker.counts["door"] == 2


def test_a_late_report_is_judged_at_the_time_the_robot_gives() -> None:
    """A robot's link was down: its node_reached comes seconds late. It entered the cabin
    while the cabin was open (no violation), and a second robot's late report shows it in an
    area while another was there (a violation the arrival order alone would miss)."""
    from guidebot.site.validate import validate_site

    checker = InvariantChecker.from_site(validate_site(safety_site()))
    feed = checker.feed
    feed("elevator_in_position", {"elevator": "lift_a", "floor": "F0", "door_open": True}, 100.0)
    feed("elevator_in_position", {"elevator": "lift_a", "floor": "F0", "door_open": False}, 108.0)
    # Reached la0 at 101 (open), reported at 110 (closed by then).
    feed("node_reached", {"robot": "R1", "node": "la0", "floor": "F0", "at": 101.0}, 110.0)
    assert checker.violations == []
    # R2 in corr_b from 120 on, reported at once; R3's late report puts it there from 121.
    feed("node_reached", {"robot": "R2", "node": "cb1", "at": 120.0}, 120.0)
    feed("node_reached", {"robot": "R3", "node": "cb1", "at": 121.0}, 125.0)
    assert [(v.invariant, v.robot, v.at) for v in checker.violations] == [("area", "R3", 121.0)]
    # A late report of R1 entering corr_b at 119 (still there): R2 and R3 came in after it.
    feed("node_reached", {"robot": "R1", "node": "cb1", "at": 119.0}, 131.0)
    assert [(v.robot, v.at) for v in checker.violations][1:] == [("R2", 120.0), ("R3", 121.0)]
    # A report that claims a time after its arrival is taken at its arrival.
    feed("node_reached", {"robot": "R4", "node": "la0", "at": 999.0}, 140.0)
    assert "while lift_a was closed or moving" in str(checker.violations[-1])
    assert checker.violations[-1].at == 140.0


def test_a_late_report_that_the_other_robot_had_left_clears_the_area_violation() -> None:
    """The server died before R1's node_reached for east (out of corr_b) was handled; its copy
    came after the restart, behind R2's entry into corr_b. R1 had left by then: no
    violation (the 30-minute fault soak counted 4 such)."""
    from guidebot.site.validate import validate_site

    checker = InvariantChecker.from_site(validate_site(safety_site()))
    feed = checker.feed
    feed("node_reached", {"robot": "R1", "node": "cb2", "at": 100.0}, 100.0)
    feed("node_reached", {"robot": "R2", "node": "cb1", "at": 130.0}, 130.0)
    assert [(v.invariant, v.robot) for v in checker.violations] == [("area", "R2")]
    feed("node_reached", {"robot": "R1", "node": "east", "at": 120.0}, 140.0)  # sent again
    assert checker.violations == []
    # One that does not take the other out leaves the violation standing.
    feed("node_reached", {"robot": "R3", "node": "cb1", "at": 150.0}, 150.0)
    feed("node_reached", {"robot": "R2", "node": "cb2", "at": 145.0}, 160.0)
    assert {(v.robot, v.at) for v in checker.violations} == {("R3", 150.0)}


def test_a_ride_is_judged_by_the_cabin_standing_open_at_its_floor_during_the_ride() -> None:
    """R1 rides lift_a from F0 to F1; the cabin's door stands open upstairs 0.8 s (time scale
    10) and R1's report of its arrival comes after it closed again: no violation (the soak
    counted "entered la1 while lift_a was closed or moving"). A ride whose cabin never stood
    open at F1, and a robot that drives into la1 from up_w after the door closed, are."""
    from guidebot.site.validate import validate_site

    checker = InvariantChecker.from_site(validate_site(safety_site()))
    feed = checker.feed
    lift = "lift_a"
    feed("elevator_in_position", {"elevator": lift, "floor": "F0", "door_open": True}, 100.0)
    feed("node_reached", {"robot": "R1", "node": "la0", "floor": "F0", "at": 101.0}, 101.0)
    feed("elevator_in_position", {"elevator": lift, "floor": "F0", "door_open": False}, 102.0)
    feed("elevator_in_position", {"elevator": lift, "floor": "F1", "door_open": True}, 110.0)
    feed("elevator_in_position", {"elevator": lift, "floor": "F1", "door_open": False}, 110.8)
    feed("node_reached", {"robot": "R1", "node": "la1", "floor": "F1", "at": 111.0}, 111.0)
    assert checker.violations == []
    # R2 boards at F1 after R1 left, rides down: the cabin never opens at F0 before its report.
    feed("node_reached", {"robot": "R1", "node": "up_w", "floor": "F1", "at": 112.0}, 112.0)
    feed("elevator_in_position", {"elevator": lift, "floor": "F1", "door_open": True}, 120.0)
    feed("node_reached", {"robot": "R2", "node": "la1", "floor": "F1", "at": 121.0}, 121.0)
    feed("elevator_in_position", {"elevator": lift, "floor": "F1", "door_open": False}, 122.0)
    feed("node_reached", {"robot": "R2", "node": "la0", "floor": "F0", "at": 130.0}, 130.0)
    assert [(v.invariant, v.robot) for v in checker.violations] == [("cabin", "R2")]
    # R1 drives back into la1 from the landing: the door closed at 122, judged as an entry
    # (R2 still stands in the lift's area below: that is an area violation besides).
    feed("node_reached", {"robot": "R1", "node": "la1", "floor": "F1", "at": 131.0}, 131.0)
    cabin = [v.robot for v in checker.violations if v.invariant == "cabin"]
    assert cabin == ["R2", "R1"]
