"""`guidebot bench emergency`: its synthetic site passes the site check, and a short real run
(robot processes on simulated CAN, the server, Modbus/TCP) prints the agreed JSON line."""

from __future__ import annotations

import asyncio
import json
import sys

import pytest

from bench.emergency import site_problems, synthetic_emergency_site

COMMAND = [sys.executable, "-m", "guidebot.cli", "bench", "emergency"]


def test_the_synthetic_site_passes_the_check_with_its_routes_and_spots() -> None:
    doc = synthetic_emergency_site(400, 4)
    assert site_problems(doc) == []
    em = doc["emergency"]
    assert em["escape_routes"] == ["escape_0", "escape_1"] and len(em["safe_spots"]) == 12
    routes = {n for a in doc["areas"] if a["id"] in em["escape_routes"] for n in a["nodes"]}
    assert not routes & set(em["safe_spots"])
    # Broken on purpose: a safe spot in the route is what the check refuses.
    doc["emergency"]["safe_spots"].append(sorted(routes)[0])
    assert any("lies in an escape route" in p for p in site_problems(doc))


@pytest.mark.timeout(300)
async def test_a_short_run_prints_the_keys_and_breaks_no_rule() -> None:
    process = await asyncio.create_subprocess_exec(
        *COMMAND,
        # At the time scale docs/emergency.md measures at: the robots walk ten times faster,
        # which asks more of the stops and the routes, not less (interleaved on a loaded
        # machine: 122 s and 158 s at time scale 1, 53 s and 90 s at 10).
        *("--robots", "2", "--runs", "2", "--time-scale", "10", "--json"),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(process.communicate(), 290)
    assert process.returncode == 0, err.decode()[-3000:]
    result = json.loads(out.decode().strip().splitlines()[-1])
    assert list(result)[:9] == [
        "site",
        "nodes",
        "robots",
        "runs",
        "alarm_to_stop_ms",
        "clear_s",
        "resume_s",
        "violations",
        "violations_by_rule",
    ]
    assert result["runs"] == 2 and result["robots"] == 2 and result["site"] == "demo"
    assert result["violations"] == 0, result
    assert result["stops_not_seen"] == 0 and result["runs_not_all_safe"] == 0, result
    # The alarm input's own filter (50 ms from the first changed sample) is part of the chain.
    assert result["alarm_to_stop_ms"]["p50"] >= 45
    assert set(result["clear_s"]) == {"p50", "p99", "max"}
    assert result["safe_s"]["max"] >= result["clear_s"]["max"]
