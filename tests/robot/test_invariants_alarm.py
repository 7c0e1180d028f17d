"""The fire alarm's rules of the invariant checker (guidebot.invariants, issue 35): each rule
broken once is found, and the same moves outside the alarm, or legal under it, are not."""

from __future__ import annotations

from guidebot.invariants import ALARM_RULES, InvariantChecker
from guidebot.site.schema import Site


def _checker() -> InvariantChecker:
    """F0: hall - c1 - c2 (the corridor, an escape route) - gallery; a door on dn; a lift
    with its cabin node l0 on F0 and l1 on F1."""
    return InvariantChecker(
        door_at={"dn": "D"},
        cabin_at={"l0": ("lift", "F0"), "l1": ("lift", "F1")},
        area_at={"c1": "corridor", "c2": "corridor", "g1": "gallery"},
        escape_at={"c1": "corridor", "c2": "corridor"},
        floor_of={"hall": "F0", "c1": "F0", "c2": "F0", "g1": "F0", "dn": "F0", "l0": "F0"}
        | {"l1": "F1", "up": "F1"},
    )


def _reach(c: InvariantChecker, robot: str, node: str, at: float) -> None:
    c.feed("node_reached", {"robot": robot, "node": node, "at": at}, at)


def _kinds(c: InvariantChecker) -> list[tuple[str, str]]:
    """The alarm rules' violations (robots share the corridor here: the area rule's own)."""
    return [(v.invariant, v.robot) for v in c.violations if v.invariant in ALARM_RULES]


def test_entering_an_escape_route_during_the_alarm_is_a_violation_leaving_it_is_not() -> None:
    c = _checker()
    _reach(c, "R1", "hall", 100.0)
    _reach(c, "R2", "c1", 100.0)
    _reach(c, "R3", "hall", 100.0)
    c.feed("emergency_declared", {"zones": [{"floors": [], "areas": []}]}, 110.0)
    _reach(c, "R3", "c1", 110.5)  # within reach_s: ordered before the alarm reached it
    _reach(c, "R2", "c2", 112.0)  # already inside: leaving by way of the route
    _reach(c, "R2", "g1", 113.0)
    _reach(c, "R1", "c1", 115.0)  # enters: broken
    assert _kinds(c) == [("escape_route", "R1")]
    [broken] = [v for v in c.violations if v.invariant == "escape_route"]
    assert "entered escape route corridor at c1" in str(broken) and broken.at == 115.0
    c.feed("emergency_resumed", {}, 120.0)
    _reach(c, "R2", "c1", 121.0)
    assert len(_kinds(c)) == 1 and c.counts["escape_route"] == 3


def test_an_alarm_on_another_floor_does_not_hold_the_route() -> None:
    c = _checker()
    _reach(c, "R1", "hall", 100.0)
    c.feed("emergency_changed", {"state": "alarm", "zones": [{"floors": ["F1"]}]}, 110.0)
    _reach(c, "R1", "c1", 115.0)
    assert c.violations == []
    c.feed("emergency_changed", {"state": "alarm", "zones": [{"areas": ["corridor"]}]}, 116.0)
    _reach(c, "R1", "hall", 117.0)
    _reach(c, "R1", "c1", 118.0)
    assert _kinds(c) == [("escape_route", "R1")]
    # input_clear still holds the zone; normal frees it.
    c.feed("emergency_changed", {"state": "input_clear", "zones": [{}]}, 119.0)
    _reach(c, "R1", "hall", 119.5)
    _reach(c, "R1", "c1", 120.0)
    c.feed("emergency_changed", {"state": "normal", "zones": []}, 121.0)
    _reach(c, "R1", "hall", 121.5)
    _reach(c, "R1", "c1", 122.0)
    assert len(_kinds(c)) == 2


def test_an_elevator_ride_started_during_the_alarm_is_a_violation() -> None:
    c = _checker()
    c.feed("elevator_in_position", {"elevator": "lift", "floor": "F0", "door_open": True}, 100.0)
    _reach(c, "R1", "l0", 101.0)
    c.feed("emergency_declared", {"zones": [{}]}, 102.0)
    # The door closes with R1 inside and the cabin goes up: the ride starts in the alarm.
    c.feed("elevator_in_position", {"elevator": "lift", "floor": "F0", "door_open": False}, 105.0)
    c.feed("elevator_in_position", {"elevator": "lift", "floor": "F1", "door_open": True}, 111.0)
    _reach(c, "R1", "l1", 112.0)
    assert _kinds(c) == [("elevator_ride", "R1")]
    assert c.violations[0].at == 105.0 and "from F0 to F1" in str(c.violations[0])


def test_a_ride_started_before_the_alarm_ends_at_its_landing_without_a_violation() -> None:
    c = _checker()
    c.feed("elevator_in_position", {"elevator": "lift", "floor": "F0", "door_open": True}, 100.0)
    _reach(c, "R1", "l0", 101.0)
    c.feed("elevator_in_position", {"elevator": "lift", "floor": "F0", "door_open": False}, 102.0)
    c.feed("emergency_declared", {"zones": [{}]}, 104.0)
    c.feed("elevator_in_position", {"elevator": "lift", "floor": "F1", "door_open": True}, 108.0)
    _reach(c, "R1", "l1", 109.0)
    assert c.violations == [] and c.counts["elevator_ride"] == 1


def test_a_door_opened_in_the_alarm_zone_is_a_violation_unless_a_person_asked() -> None:
    c = _checker()
    c.feed("door_opened", {"door": "D"}, 100.0)  # no alarm
    c.feed("door_closed", {"door": "D"}, 101.0)
    c.feed("emergency_declared", {"zones": [{"floors": ["F0"]}]}, 105.0)
    c.feed("door_opened", {"door": "D"}, 105.4)  # ordered just before the alarm reached
    c.feed("door_closed", {"door": "D"}, 106.0)
    c.feed("door_opened_by_hand", {"door": "D", "by": "ops"}, 107.0)
    c.feed("door_opened", {"door": "D"}, 108.0)  # staff opened it: allowed
    c.feed("door_closed", {"door": "D"}, 109.0)
    assert c.violations == []
    c.feed("door_opened", {"door": "D"}, 150.0)  # long after the person's order: the fleet's
    assert _kinds(c) == [("alarm_door", "-")]
    assert "door D opened during the fire alarm" in str(c.violations[0])


def test_the_demo_museum_gives_the_checker_its_escape_routes(demo_site: Site) -> None:
    c = InvariantChecker.from_site(demo_site)
    assert demo_site.emergency is not None
    routes = set(demo_site.emergency.escape_routes)
    assert routes and set(c.escape_at.values()) == routes
    assert set(c.floor_of) == {n.id for n in demo_site.nodes}
