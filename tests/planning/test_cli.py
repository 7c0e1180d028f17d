"""``guidebot plan`` end to end: a profile or a recorded day in, a table and one JSON line out;
wrong options refused with the reason (docs/planning.md)."""

from __future__ import annotations

import asyncio
import datetime as dt
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from backend.db import make_engine, make_sessionmaker, migrate
from backend.db.models import EventRow
from backend.planning.cli import parse_robots
from backend.planning.profile import PlanError
from backend.planning.recorded import read_day, read_replay
from guidebot.cli import main
from guidebot.site.yamlio import load_site_file
from tests.planning.test_sim import DEMO, DEMO_PROFILE


def plan(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(main, ["plan", "--site", str(DEMO), *args])
    return result.exit_code, result.output


def test_a_profile_gives_one_row_per_fleet_and_policy() -> None:
    code, output = plan(
        "--visitors", str(DEMO_PROFILE), "--robots", "1..3", "--policy", "all", "--json"
    )
    assert code == 0, output
    result = json.loads(output.strip().splitlines()[-1])
    assert result["requests"] == 120 and result["day_h"] == 10
    rows = [(r["policy"], r["robots"]) for r in result["fleets"]]
    assert rows == [(p, n) for p in ("nearest", "longest-idle") for n in (1, 2, 3)]
    for row in result["fleets"]:
        assert row["served"] + row["refused"] + row["abandoned"] == 120
        assert 0 < row["utilisation"] <= 1
    assert "wait p95" in output.splitlines()[0]


def test_with_json_stdout_is_the_json_object_alone_and_the_table_goes_to_stderr() -> None:
    """``guidebot plan --json | jq`` read the table's lines first: stdout is one JSON line."""
    args = ["plan", "--site", str(DEMO), "--visitors", str(DEMO_PROFILE), "--robots", "2"]
    result = CliRunner().invoke(main, [*args, "--json"])
    assert result.exit_code == 0, result.output
    [line] = result.stdout.splitlines()
    assert [row["robots"] for row in json.loads(line)["fleets"]] == [2]
    assert "wait p95" in result.stderr.splitlines()[0]
    table = CliRunner().invoke(main, args)
    assert "wait p95" in table.stdout.splitlines()[0]  # without --json: the table, on stdout


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("8..2", "ends below its start \\(try 2..8\\)"),
        ("0..3", "from 1 to 200"),
        ("many", "give a number, a range like 2..8"),
    ],
)
def test_a_wrong_robots_range_is_refused(text: str, message: str) -> None:
    with pytest.raises(PlanError, match=message):
        parse_robots(text)
    code, output = plan("--visitors", str(DEMO_PROFILE), "--robots", text)
    assert code == 2 and "--robots" in output


def test_an_unknown_tour_in_the_profile_is_refused(tmp_path: Path) -> None:
    profile = tmp_path / "crowd.yaml"
    profile.write_text("hours: [{ground: 3, roof: 2}]\n", encoding="utf-8")
    code, output = plan("--visitors", str(profile))
    assert code == 2
    assert "unknown tour(s) roof; the site's tours: ground, upstairs, highlights" in output


def test_one_source_of_visitors_is_needed() -> None:
    code, output = plan("--robots", "2")
    assert code == 2 and "give one source of visitors" in output
    code, output = plan("--day", "sqlite+aiosqlite:///x.db")
    assert code == 2 and "--day needs --date" in output


async def test_a_recorded_day_replays_its_tour_requests(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'day.db'}"
    engine = make_engine(url)
    await migrate(engine)
    noon = 1_780_000_000 // 86400 * 86400 + 12 * 3600  # a UTC noon
    rows = [
        EventRow(
            at=noon + 60 * i,
            kind="task_created",
            source="tm",
            data={"task_id": f"t{i}", "kind": "tour", "tour": tour, "state": "queued"},
        )
        for i, tour in enumerate(["ground", "highlights", "removed", "ground"])
    ]
    rows.append(
        EventRow(
            at=noon,
            kind="task_created",
            source="tm",
            data={"task_id": "c", "kind": "charge", "state": "queued"},
        )
    )
    explained = {"task_id": "t0", "index": 2, "total": 5, "stage": "explained"}
    rows.append(
        EventRow(at=noon + 500, kind="task_point 2/5 explained", source="tm", data=explained)
    )
    async with make_sessionmaker(engine)() as session:
        session.add_all(rows)
        await session.commit()
    await engine.dispose()
    date = dt.datetime.fromtimestamp(noon, dt.UTC).date().isoformat()
    day = await read_day(url, date, "UTC", load_site_file(DEMO), stop_following=0.0, seed=1)
    assert day.requests[0].follow == 2  # the recording's: it left after the second point
    assert day.requests[2].follow == 5  # nobody stops by default: the whole ground tour
    assert [(r.at, r.tour) for r in day.requests] == [
        (0, "ground"),
        (60, "highlights"),
        (180, "ground"),
    ]
    assert (day.skipped, day.day_s, day.start) == (1, 3600, noon)


def test_the_bench_times_a_day_and_prints_one_json_line() -> None:
    result = CliRunner().invoke(
        main, ["bench", "plan", "--hours", "2", "--per-hour", "30", "--robots", "3", "--json"]
    )
    assert result.exit_code == 0, result.output
    last = json.loads(result.output.strip().splitlines()[-1])
    assert (last["requests"], last["robots"], last["hours"]) == (60, 3, 2)
    assert last["wall_s"] >= last["sim_s"] >= 0 and last["goal_s"] == 180.0


async def write_live_day(url: str, noon: float) -> None:
    """One robot connected; two ground tours asked a minute apart, the robot at the first
    point 30 s and 200 s after each request."""
    engine = make_engine(url)
    await migrate(engine)
    rows = [EventRow(at=noon - 10, kind="robot_connected", source="hub", data={"robot": "R1"})]
    for i, (asked, waited) in enumerate([(0, 30), (60, 200)]):
        task = {"task_id": f"t{i}", "kind": "tour", "tour": "ground", "state": "queued"}
        rows.append(EventRow(at=noon + asked, kind="task_created", source="tm", data=task))
        arrived = {"task_id": f"t{i}", "index": 1, "total": 5, "stage": "arrived"}
        rows.append(
            EventRow(
                at=noon + asked + waited, kind="task_point 1/5 arrived", source="tm", data=arrived
            )
        )
    async with make_sessionmaker(engine)() as session:
        session.add_all(rows)
        await session.commit()
    await engine.dispose()


def test_the_check_compares_measured_waits_with_the_plan(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'live.db'}"
    noon = 1_780_000_000 // 86400 * 86400 + 12 * 3600
    asyncio.run(write_live_day(url, noon))
    date = dt.datetime.fromtimestamp(noon, dt.UTC).date().isoformat()
    result = CliRunner().invoke(
        main,
        ["bench", "plan-check", "--site", str(DEMO), "--db", url, "--date", date, "--json"],
    )
    assert result.exit_code == 0, result.output
    last = json.loads(result.output.strip().splitlines()[-1])
    assert (last["requests"], last["compared"], last["robots"]) == (2, 2, 1)
    assert last["measured"] == {"p50_s": 30.0, "p95_s": 200.0}
    planned = last["planned"]
    assert last["error"]["p50"] == round(planned["p50_s"] / 30.0 - 1, 3)


def test_plan_replays_a_recorded_day_over_other_fleets(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'live.db'}"
    noon = 1_780_000_000 // 86400 * 86400 + 12 * 3600
    asyncio.run(write_live_day(url, noon))
    date = dt.datetime.fromtimestamp(noon, dt.UTC).date().isoformat()
    code, output = plan("--day", url, "--date", date, "--robots", "1..2", "--json")
    assert code == 0, output
    result = json.loads(output.strip().splitlines()[-1])
    assert result["source"] == {
        "date": date,
        "tz": "UTC",
        "skipped": 0,
        "from": noon,
        "pace": {"move": 1.0, "talk": 1.0},  # no point both reached and explained: nominal
    }
    assert [(r["robots"], r["served"]) for r in result["fleets"]] == [(1, 2), (2, 2)]
    code, output = plan("--day", url, "--date", "2026-13-01")
    assert code == 2 and "2026-13-01" in output


def test_plan_takes_a_replay_file_as_its_visitors(tmp_path: Path) -> None:
    """``guidebot replay --out`` carries the period's tour requests, and ``plan --replay`` plays
    them as it plays a recorded day."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'live.db'}"
    noon = 1_780_000_000 // 86400 * 86400 + 12 * 3600
    asyncio.run(write_live_day(url, noon))
    start = dt.datetime.fromtimestamp(noon - 3600, dt.UTC).isoformat()
    end = dt.datetime.fromtimestamp(noon + 3600, dt.UTC).isoformat()
    out = tmp_path / "hour.json"
    exported = CliRunner().invoke(
        main, ["replay", "--from", url, "--start", start, "--end", end, "--out", str(out)]
    )
    assert exported.exit_code == 0, exported.output
    code, output = plan("--replay", str(out), "--robots", "1..2", "--json")
    assert code == 0, output
    result = json.loads(output.strip().splitlines()[-1])
    assert result["requests"] == 2 and result["source"]["replay"] == str(out)
    assert result["source"]["from"] == noon
    assert [(r["robots"], r["served"]) for r in result["fleets"]] == [(1, 2), (2, 2)]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("not json", "not a replay file \\(not JSON\\)"),
        ('{"events": []}', 'no "guidebot_replay": 1'),
        ('{"guidebot_replay": 1, "events": []}', "holds no tour request"),
    ],
)
def test_a_file_that_is_no_replay_is_refused(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "x.json"
    path.write_text(content)
    with pytest.raises(PlanError, match=message):
        read_replay(path, load_site_file(DEMO), stop_following=0.0, seed=1)
    code, output = plan("--replay", str(path))
    assert code == 2 and "--replay" in output


def test_two_sources_of_visitors_are_refused(tmp_path: Path) -> None:
    code, output = plan("--visitors", str(DEMO_PROFILE), "--replay", str(tmp_path / "x.json"))
    assert code == 2 and "give one source of visitors" in output
