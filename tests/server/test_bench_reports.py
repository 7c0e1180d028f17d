"""bench reports, briefly: a few days of a venue folded and every figure timed (docs/reports.md)."""

from __future__ import annotations

import json

from click.testing import CliRunner

from bench.reports import main


def test_bench_reports_folds_the_log_and_times_every_figure() -> None:
    result = CliRunner().invoke(main, ["--events", "20000", "--robots", "2", "--json"])
    assert result.exit_code == 0, result.output
    figures = json.loads(result.output.strip().splitlines()[-1])
    assert figures["folded"] == figures["events"] >= 10_000
    assert figures["rollup_rows"] > 0 and figures["db_mb"] > 0
    for period in ("day", "week", "year"):
        assert figures["by_period"][period]["p99"] >= figures["by_period"][period]["p50"] > 0
        assert figures["summary_ms"][period] > 0
    assert set(figures["by_figure"]) == {
        "tasks",
        "waits",
        "following",
        "stops",
        "robots",
        "incidents",
        "heat",
    }
