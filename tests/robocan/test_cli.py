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
    status = json.loads(result.output.strip().splitlines()[-1])
    (bus,) = status["buses"]
    table = {row["module_id"]: row for row in bus["modules"]}
    assert set(table) == {0x02, 0x04, 0x08, 0x10, 0x20, 0x40}
    assert table[0x02]["kind"] == "motor_controller" and table[0x02]["firmware"] == "2.1"
    assert bus["counters"]["bad_frame"] == 0 and bus["counters"]["frames_rx"] > 0
    assert "0x10 sonar_ring_10" in result.output and "requeried 0" in result.output
    analysed = runner.invoke(main, ["robocan", "analyze", str(log), "--json"])
    assert analysed.exit_code == 0, analysed.output
    modules = json.loads(analysed.output.strip().splitlines()[-1])["modules"]
    assert modules["0x02"]["rx_frames"] > 0  # the velocity commands it received


def test_run_refuses_a_bad_bus() -> None:
    result = CliRunner().invoke(main, ["robocan", "run", "--bus", "nonsense", "--seconds", "0.1"])
    assert result.exit_code != 0 and "interface:channel" in result.output


def test_drivers_lists_the_built_in_drivers() -> None:
    result = CliRunner().invoke(main, ["robocan", "drivers"])
    assert result.exit_code == 0
    expected = "pid_velocity: robot_agent.robocan.entities.BaseDriver (critical) [built-in]"
    assert expected in result.output


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
