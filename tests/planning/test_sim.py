"""The planner's simulation against waits worked out by hand, and its sense on the demo
museum (docs/planning.md)."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from backend.planning.profile import PlanError, Request, draw, load_profile, parse_profile
from backend.planning.recorded import learn_pace
from backend.planning.sim import simulate
from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site
from guidebot.site.yamlio import load_site_file

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "sites" / "demo_museum.yaml"
DEMO_PROFILE = ROOT / "sites" / "profiles" / "demo_museum_300.yaml"

# The tiny site: A and B 100 m apart, one point at each with nothing to say, a robot at 1 m/s
# starting at A. A tour A -> B takes 2 s (facing people at A) + 100 s + 3 s ("continue?") +
# 2 s (at B) = 107 s from A; from B the robot first drives 100 s back to A.
TOUR_FROM_A_S = 107.0
BACK_TO_A_S = 100.0


def tiny_site(**changes: object) -> Site:
    return Site.model_validate(
        {
            "name": "tiny",
            "floors": [{"id": "F0"}],
            "nodes": [
                {"id": "A", "floor": "F0", "x": 0.0, "y": 0.0},
                {"id": "B", "floor": "F0", "x": 100.0, "y": 0.0},
            ],
            "edges": [{"a": "A", "b": "B"}],
            "pois": [{"id": "pa", "node": "A"}, {"id": "pb", "node": "B"}],
            "tours": [{"id": "ab", "points": ["pa", "pb"]}],
            "wait_points": [{"id": "w", "node": "A"}],
            "robots": [
                {"name": "R1", "token": "robot-R1-token", "start_node": "A", "max_speed_mps": 1.0}
            ],
        }
        | changes
    )


def run_tiny(per_hour: int, **changes: object) -> list[float]:
    site = tiny_site(**changes)
    profile = parse_profile({"hours": [{"ab": per_hour}], "spacing": "even"}, site)
    outcome = simulate(site, SiteGraph(site), draw(profile, site), robots=1, day_s=3600)
    return outcome.waits_s


def test_one_robot_keeping_up_waits_for_nothing_back_at_its_wait_point() -> None:
    # Every 300 s: the tour ends at B 107 s after the start, the robot drives back to its wait
    # point A (100 s, the Task Manager's idle errand) and is there before the next request.
    assert run_tiny(12) == pytest.approx([0.0] * 12)


def test_one_robot_with_nowhere_to_go_waits_at_the_last_point() -> None:
    # No wait point: the robot stays at B, each later request waits for the drive to A.
    assert run_tiny(12, wait_points=[]) == pytest.approx([0.0] + [BACK_TO_A_S] * 11)


def test_one_robot_falling_behind_waits_grow_by_the_shortfall() -> None:
    # Every 150 s, each task after the first takes 207 s: from the second on, each request
    # waits 57 s more than the one before.
    waits = run_tiny(24)
    cycle = TOUR_FROM_A_S + BACK_TO_A_S
    expected = [0.0] + [BACK_TO_A_S + (cycle - 150) * (k - 1) for k in range(1, 24)]
    assert waits == pytest.approx(expected)


def test_visitors_who_stop_following_end_the_tour_at_the_first_point() -> None:
    site = tiny_site()
    requests = [Request(0.0, "ab", 1), Request(10.0, "ab", 1)]
    outcome = simulate(site, SiteGraph(site), requests, robots=1, day_s=3600)
    assert outcome.waits_s == pytest.approx([0.0, 0.0])  # 2 s at A, free at A again
    assert outcome.busy_s == pytest.approx(4.0)


def test_impatient_visitors_leave_and_a_full_queue_refuses() -> None:
    left = simulate(
        tiny_site(),
        SiteGraph(tiny_site()),
        draw(parse_profile({"hours": [{"ab": 24}], "spacing": "even"}, tiny_site()), tiny_site()),
        robots=1,
        day_s=3600,
        patience_s=120.0,
    )
    assert left.abandoned > 0
    assert len(left.waits_s) + left.abandoned == 24
    assert max(w - BACK_TO_A_S for w in left.waits_s) <= 120.0
    refused = simulate(
        tiny_site(),
        SiteGraph(tiny_site()),
        [Request(float(i), "ab", 2) for i in range(5)],
        robots=1,
        day_s=3600,
        queue_limit=2,
    )
    assert (refused.refused, len(refused.waits_s)) == (2, 3)


def test_more_robots_never_make_the_demo_museum_wait_longer() -> None:
    site = load_site_file(DEMO)
    graph = SiteGraph(site)
    requests = draw(load_profile(DEMO_PROFILE, site), site)
    summaries = [
        simulate(site, graph, requests, robots=n, day_s=36000).summary(10) for n in range(1, 9)
    ]
    for fewer, more in itertools.pairwise(summaries):
        assert more["wait_p50_s"] <= fewer["wait_p50_s"]
        assert more["wait_p95_s"] <= fewer["wait_p95_s"]
        assert more["abandoned"] <= fewer["abandoned"]
        assert more["utilisation"] <= fewer["utilisation"]
    assert summaries[0]["wait_p95_s"] > summaries[-1]["wait_p95_s"]


def test_an_unknown_policy_or_no_robot_is_refused() -> None:
    site = tiny_site()
    with pytest.raises(PlanError, match="unknown policy 'fastest'; known: nearest, longest-idle"):
        simulate(site, SiteGraph(site), [], robots=1, policy="fastest", day_s=3600)
    with pytest.raises(PlanError, match="at least one robot"):
        simulate(site, SiteGraph(site), [], robots=0, day_s=3600)


def test_the_pace_learned_from_a_recording_scales_the_tours() -> None:
    # The tiny tour recorded twice as slow as nominal: 4 s at A (nominal 2), 206 s to B (103).
    site = tiny_site()
    created = {"task_id": "t", "kind": "tour", "tour": "ab"}
    rows = [(0.0, "task_created", created)]
    for at, index, stage in [(0.0, 1, "arrived"), (4.0, 1, "explained"), (210.0, 2, "arrived")]:
        mark = {"task_id": "t", "index": index, "stage": stage}
        rows.append((at, f"task_point {index}/2 {stage}", mark))
    pace = learn_pace(rows, site)
    assert (pace.move, pace.talk) == (2.0, 2.0)
    outcome = simulate(
        site, SiteGraph(site), [Request(0.0, "ab", 2)], robots=1, day_s=3600, pace=pace
    )
    assert outcome.busy_s == pytest.approx(2 * TOUR_FROM_A_S)
    profile = parse_profile({"hours": [{"ab": 1}], "pace": {"move": 2, "talk": 2}}, site)
    assert profile.pace == pace
    with pytest.raises(PlanError, match="pace must be"):
        parse_profile({"hours": [{"ab": 1}], "pace": {"walk": 2}}, site)
