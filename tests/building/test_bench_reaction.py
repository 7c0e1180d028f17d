"""`guidebot bench reaction`: a short real run prints the agreed JSON line, the figure and the
per-run CSV; a press too short to pass the filter is refused before anything starts."""

from __future__ import annotations

import asyncio
import csv
import json
import sys
from pathlib import Path

from bench.reaction import OURS_FOR_PAPER, PAPER_ROWS

COMMAND = [sys.executable, "-m", "guidebot.cli", "bench", "reaction"]


async def run(*args: str) -> tuple[int, str, str]:
    process = await asyncio.create_subprocess_exec(
        *COMMAND, *args, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    out, err = await asyncio.wait_for(process.communicate(), 110)
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


async def test_short_run_prints_table_json_png_and_csv(tmp_path: Path) -> None:
    png, table = tmp_path / "fig.png", tmp_path / "runs.csv"
    code, out, err = await run(
        "--runs", "4", "--robots", "2", "--png", str(png), "--csv", str(table)
    )
    assert code == 0, err
    lines = out.strip().splitlines()
    result = json.loads(lines[-1])
    assert list(result) == [
        "runs",
        "robots",
        "steps",
        "end_to_end_ms",
        "overhead_ms",
        "paper_avg_ms",
    ]
    assert result["runs"] == 4 and result["robots"] == 2 and result["paper_avg_ms"] == 2365
    steps = result["steps"]
    assert all(set(v) == {"avg", "max", "min", "dev"} for v in steps.values())
    # The floor of the chain: the 200 ms filter from the first changed sample, and a poll wait
    # that is never more than one period (200 ms) plus scheduling. The filter compares the
    # samples' schedule slots (exactly 200 ms apart), but the step is timed between the wall
    # clock moments the two samples were handled: a first sample handled late on a busy machine
    # shortens it by that lateness (a CI run measured 194.8 ms). A missing filter would give ~0.
    assert steps["filter"]["min"] >= 180
    assert 0 <= steps["modbus_wait"]["min"] and steps["modbus_wait"]["max"] <= 260
    e2e = result["end_to_end_ms"]
    assert e2e["p50"] >= 200 + steps["modbus_wait"]["min"]
    assert result["overhead_ms"]["p50"] > 0
    # The table names the paper's rows beside ours.
    text = "\n".join(lines[:-1])
    for row, *_ in PAPER_ROWS:
        assert row in text
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with table.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 4
    assert all(float(r["moving_at"]) > float(r["pressed_at"]) for r in rows)
    assert set(OURS_FOR_PAPER) == {row for row, *_ in PAPER_ROWS}


async def test_a_press_shorter_than_filter_plus_period_is_refused() -> None:
    code, out, err = await run("--runs", "1", "--press-ms", "300")
    assert code == 2
    assert "too short" in err and "400 ms" in err
    assert out == ""
