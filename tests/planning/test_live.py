"""``guidebot plan --live``: the day played on the real server, Task Manager and Traffic Manager
with simulated robots and building (separate processes on loopback, 20 times the wall clock),
then measured from the server's event log (docs/planning.md, "The live run")."""

from __future__ import annotations

import asyncio
import datetime as dt
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from backend.planning.live import LiveOptions, run_live
from backend.planning.measure import read_events
from backend.planning.profile import PlanError, Request
from guidebot.cli import main
from guidebot.site.yamlio import load_site_file
from tests.planning.test_cli import write_live_day
from tests.planning.test_sim import DEMO

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


def _explained(events: list, task_ids: dict[str, int]) -> dict[int, int]:
    """Request index -> the last point its tour explained."""
    last: dict[int, int] = {}
    for _, kind, _, d in events:
        i = task_ids.get(str(d.get("task_id")))
        if i is not None and kind.startswith("task_point") and d.get("stage") == "explained":
            last[i] = max(last.get(i, 0), int(d["index"]))
    return last


async def test_a_live_run_serves_answers_and_gives_up_as_the_visitors_would(
    tmp_path: Path,
) -> None:
    site = load_site_file(DEMO)
    requests = [
        Request(0.0, "ground", 1),  # leaves after the first point: "no" at the first question
        Request(1.0, "highlights", 3),  # yes, yes: the whole tour, upstairs by the elevator
        Request(5.0, "ground", 5),  # both robots busy: gives up after 30 s
    ]
    outcome = await run_live(
        DEMO,
        site,
        requests,
        robots=2,
        day_s=600.0,
        patience_s=30.0,
        options=LiveOptions(scale=20.0, can=False, workdir=tmp_path),
    )
    assert sorted(outcome.wait_of) == [0, 1]
    assert outcome.abandoned == 1 and outcome.refused == 0
    assert all(0 < w < 600 for w in outcome.waits_s)
    summary = outcome.summary(10.0)
    assert summary["served"] == 2 and summary["failed"] == 0 and summary["unfinished"] == 0
    assert summary["mode"] == "live" and summary["time_scale"] == 20.0
    assert 0 < summary["utilisation"] <= 1
    # The Traffic Manager's lock of the elevator area and the building's cabin are in it.
    assert summary["lock_wait"]["elevator"]["count"] >= 1
    assert summary["elevator_wait"]["lift"]["count"] >= 1
    assert summary["busiest_areas"][0]["count"] >= 1 and summary["busiest_doors"]
    events = await read_events(f"sqlite+aiosqlite:///{tmp_path / 'robots-2' / 'plan.db'}")
    created = [d["task_id"] for _, k, _, d in events if k == "task_created" and d["kind"] == "tour"]
    assert len(created) == 3
    ids = {task: i for i, task in enumerate(created)}
    assert _explained(events, ids) == {0: 1, 1: 3}
    cancelled = [d["task_id"] for _, k, _, d in events if k == "task_cancelled"]
    assert cancelled == [created[2]]


def test_a_live_run_refuses_a_time_scale_of_zero(tmp_path: Path) -> None:
    site = load_site_file(DEMO)
    with pytest.raises(PlanError, match="--time-scale"):
        asyncio.run(
            run_live(
                DEMO,
                site,
                [Request(0.0, "ground", 1)],
                robots=1,
                day_s=60.0,
                options=LiveOptions(scale=0.0, workdir=tmp_path),
            )
        )


def test_the_check_plans_a_recording_on_the_live_fleet(tmp_path: Path) -> None:
    """``guidebot bench plan-check --live``: the recorded requests played on the real fleet of
    the recording's size, measured as the recording was."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'recorded.db'}"
    noon = 1_780_000_000 // 86400 * 86400 + 12 * 3600
    asyncio.run(write_live_day(url, noon))
    date = dt.datetime.fromtimestamp(noon, dt.UTC).date().isoformat()
    args = ["bench", "plan-check", "--site", str(DEMO), "--db", url, "--date", date]
    args += ["--live", "--time-scale", "20", "--no-can", "--workdir", str(tmp_path), "--json"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    last = json.loads(result.output.strip().splitlines()[-1])
    assert (last["mode"], last["time_scale"], last["robots"]) == ("live", 20.0, 1)
    assert (last["requests"], last["compared"]) == (2, 2)
    assert last["measured"] == {"p50_s": 30.0, "p95_s": 200.0}
    assert last["planned"]["p50_s"] > 0 and last["planned"]["p95_s"] > last["planned"]["p50_s"]
