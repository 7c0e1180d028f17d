"""`guidebot bench soak`, short: the fleet in separate processes under every kind of fault
for a minute loses no task, breaks no safety invariant and logs no unhandled error."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path

import pytest

from bench.soak_bookings import walk_ups
from bench.soak_faults import ALL_KINDS, KINDS, schedule
from bench.soak_measures import Measures, percentiles
from bench.soak_watch import TaskSeen, Watch
from guidebot.invariants import InvariantChecker

KEYS = [
    "minutes",
    "robots",
    "tasks_requested",
    "tasks_done",
    "tasks_cancelled",
    "tasks_failed",
    "tasks_lost",
    "walk_ups_requested",
    "walk_ups_done",
    "area_violations",
    "door_violations",
    "elevator_violations",
    "alarm_violations",
    "faults_injected",
    "unhandled_errors",
    "max_rss_mb",
    "done_share",
    "failures_by_reason",
    "handover_s",
    "skipped_stops",
    "utilisation",
    "touring_spread",
]
SEED = 3


def test_the_fault_plan_is_reproducible_and_deals_every_kind() -> None:
    def plan(seed: int) -> list[str]:
        faults = schedule(seed, 60.0, 5.0, ["R1", "R2"], ["m1", "m2"], ["lift"], ["d1"])
        assert {f.kind for f in faults} == set(KINDS), faults
        return [str(f) for f in faults]

    assert plan(SEED) == plan(SEED)
    assert plan(SEED) != plan(SEED + 1)


def test_the_fire_alarm_fault_is_dealt_on_demand_for_site_seconds() -> None:
    """``--fire-alarm``: the kind joins the deck; it lasts 20-60 site seconds, wall seconds
    at the time scale; the default deck stays as it was."""
    targets = (["R1"], ["m1"], ["lift"], ["d1"])
    faults = schedule(
        SEED, 120.0, 5.0, *targets, alarms=["fire_main"], kinds=ALL_KINDS, time_scale=10.0
    )
    alarms = [f for f in faults if f.kind == "fire_alarm"]
    assert alarms and all(f.target == "fire_main" and 2.0 <= f.hold_s <= 6.0 for f in alarms)
    assert "fire_alarm" not in {f.kind for f in schedule(SEED, 120.0, 5.0, *targets)}
    with pytest.raises(ValueError, match="needs an alarm input"):
        schedule(SEED, 60.0, 5.0, *targets, kinds=ALL_KINDS)
    with pytest.raises(ValueError, match="unknown fault kind"):
        schedule(SEED, 60.0, 5.0, *targets, kinds=("flood",))


def test_failure_reasons_are_counted_with_their_numbers_blurred() -> None:
    watch = Watch("http://127.0.0.1:1", "token", InvariantChecker({}, {}, {}), 30.0)
    watch.tasks = {
        "a": TaskSeen("failed", "R3: timed out waiting for area elevator after 600 s", "p"),
        "b": TaskSeen("failed", "R10: timed out waiting for area elevator after 600 s", "p"),
        "c": TaskSeen("failed", "navigation to gc1 failed: stuck 9.50 m from (5.0, 8.0)", "p"),
        "d": TaskSeen("done", "", "p"),
    }
    assert watch.failure_reasons() == {
        "R#: timed out waiting for area elevator after # s": 2,
        "navigation to gc# failed: stuck # m from (#, #)": 1,
    }


def test_tours_done_handovers_skips_and_touring_time_are_measured() -> None:
    m = Measures()
    events = [  # a tour on R1, handed over to R2 at t=30; a visit on R2 from t=100
        ("task_created", {"task_id": "a", "state": "queued", "robot": None}, 0.0),
        ("task_assigned", {"task_id": "a", "state": "assigned", "robot": "R1"}, 10.0),
        ("task_started", {"task_id": "a", "state": "running", "robot": "R1"}, 12.0),
        ("task_requeued", {"task_id": "a", "state": "queued", "robot": None}, 30.0),
        ("task_assigned", {"task_id": "a", "state": "assigned", "robot": "R2"}, 31.0),
        ("task_done", {"task_id": "a", "state": "done", "robot": "R2"}, 91.0),
        ("task_assigned", {"task_id": "b", "state": "assigned", "robot": "R2"}, 100.0),
        ("task_assigned", {"task_id": "z", "state": "assigned", "robot": "R1"}, 100.0),
    ]
    for kind, data, at in events:
        m.feed_event(kind, data, at)
    m.feed_task("a", {"handover": {"arrived_after_s": 12.5}})
    m.feed_task("b", {"handover": None})
    m.feed_history("a", [{"event": "point 2/5 skipped"}, {"event": "point 3/5 arrived"}])
    tasks = {
        "a": TaskSeen("done", "", "p", kind="tour"),
        "b": TaskSeen("failed", "door jammed", "p", kind="go_to_poi"),
        "c": TaskSeen("cancelled", "", "p", cancelled_by="requester"),
    }  # "z" is an internal errand: not a visitor's task
    result = m.result(tasks, ["R1", "R2", "R3"], 200.0, 110.0)
    assert result["done_share"] == 0.5  # a done, b failed; c cancelled by its visitor: left out
    assert result["handover_s"] == {"p50": 12.5, "p99": 12.5, "n": 1}
    assert result["skipped_stops"] == 1
    assert result["utilisation"] == {"R1": 0.1, "R2": 0.35, "R3": 0.0}  # 20 s, 60 + 10 s, 0
    assert result["touring_spread"] == round(70 / 30, 3)
    assert percentiles([]) == {"p50": None, "p99": None}
    assert percentiles(float(i) for i in range(1, 101)) == {"p50": 50.0, "p99": 99.0}


@pytest.mark.timeout(480)
async def test_a_short_soak_loses_nothing_and_breaks_no_invariant(tmp_path: Path) -> None:
    process = await asyncio.create_subprocess_exec(
        *(sys.executable, "-m", "guidebot.cli", "bench", "soak", "--minutes", "1"),
        *("--robots", "3", "--seed", str(SEED), "--time-scale", "10", "--fault-every", "5"),
        *("--drain", "240", "--workdir", str(tmp_path), "--json"),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(process.communicate(), 470)
    report = err.decode(errors="replace")
    assert process.returncode == 0, report
    assert "soak: failure reasons: {" in report
    result = json.loads(out.decode().strip().splitlines()[-1])
    assert list(result) == KEYS
    assert result["robots"] == 3 and result["minutes"] == 1
    assert result["tasks_requested"] > 0 and result["tasks_done"] > 0, report
    assert result["tasks_lost"] == 0, report
    assert result["area_violations"] == 0, report
    assert result["door_violations"] == 0, report
    assert result["elevator_violations"] == 0, report
    assert result["alarm_violations"] == 0, report
    assert result["unhandled_errors"] == 0, report
    assert set(result["faults_injected"]) == set(KINDS)
    assert sum(result["faults_injected"].values()) >= 6, result["faults_injected"]
    assert {"server", "building_sim", "R1", "R2", "R3"} <= set(result["max_rss_mb"])
    assert 0 <= result["done_share"] <= 1, result
    assert set(result["utilisation"]) == {"R1", "R2", "R3"}, result
    assert set(result["handover_s"]) == {"p50", "p99", "n"}, result


def test_walk_ups_leave_out_the_booked_tours_and_their_ways_to_the_meeting_point() -> None:
    tasks = {
        "a": TaskSeen("done", "", "panel-1"),
        "b": TaskSeen("failed", "door jammed", "panel-2"),
        "c": TaskSeen("done", "", "booking:x1@1800000000"),
        "d": TaskSeen("cancelled", "the booked tour starts", "booking:x1@1800000000:meet"),
    }
    assert walk_ups(tasks) == {"walk_ups_requested": 2, "walk_ups_done": 1}
