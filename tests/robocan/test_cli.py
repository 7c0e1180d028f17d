"""The command line: run with recording, drivers, and the benchmark's closing JSON line."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from guidebot.cli import main


def test_run_records_a_log_that_analyze_reads(tmp_path: Path) -> None:
    log = tmp_path / "bellbot.asc"
    channel = f"virtual:cli-run-{tmp_path.name}"
    runner = CliRunner()
    result = runner.invoke(
        main,
        [
            "robocan",
            "run",
            "--bus",
            channel,
            "--seconds",
            "0.5",
            "--move",
            "0.3",
            "--record",
            str(log),
        ],
    )
    assert result.exit_code == 0, result.output
    table = json.loads(result.output[result.output.index("[") :])
    assert {row["module_id"] for row in table} == {0x02, 0x04, 0x08, 0x10, 0x20, 0x40}
    analysed = runner.invoke(main, ["robocan", "analyze", str(log), "--json"])
    assert analysed.exit_code == 0, analysed.output
    modules = json.loads(analysed.output.strip().splitlines()[-1])["modules"]
    assert modules["0x02"]["rx_frames"] > 0  # the velocity commands it received


def test_run_refuses_a_bad_bus() -> None:
    result = CliRunner().invoke(main, ["robocan", "run", "--bus", "nonsense", "--seconds", "0.1"])
    assert result.exit_code != 0 and "interface:channel" in result.output


def test_drivers_lists_the_entry_points() -> None:
    result = CliRunner().invoke(main, ["robocan", "drivers"])
    assert result.exit_code == 0
    assert "pid_velocity: robot_agent.robocan.entities.BaseDriver (critical)" in result.output


def test_bench_prints_the_issue_keys_last() -> None:
    result = CliRunner().invoke(
        main, ["bench", "robocan", "--cycles", "1", "--frames", "40000", "--samples", "3", "--json"]
    )
    assert result.exit_code == 0, result.output
    last = json.loads(result.output.strip().splitlines()[-1])
    assert set(last) == {
        "plug_detect_ms",
        "unplug_detect_ms",
        "frames_per_s_at_50pct_cpu",
        "command_to_frame_ms",
    }
    assert set(last["plug_detect_ms"]) == {"p50", "p99"}
    assert last["unplug_detect_ms"]["p50"] > 0 and last["frames_per_s_at_50pct_cpu"] > 0
