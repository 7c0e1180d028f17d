"""`guidebot bench soak`, short: the fleet in separate processes under every kind of fault
for a minute loses no task, breaks no safety invariant and logs no unhandled error."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path

import pytest

from bench.soak_faults import ALL_KINDS, KINDS, schedule
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
    "area_violations",
    "door_violations",
    "elevator_violations",
    "alarm_violations",
    "faults_injected",
    "unhandled_errors",
    "max_rss_mb",
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
