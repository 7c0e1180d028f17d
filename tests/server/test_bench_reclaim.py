"""bench reclaim, briefly: 64 robots leave a running server at once, the reclaim follows on its
own timer, and the JSON names both stalls."""

from __future__ import annotations

import json

from click.testing import CliRunner

from bench.hub_reclaim import main


def test_bench_reclaim_reports_the_leave_and_the_reclaim_apart() -> None:
    args = ["--nodes", "400", "--clients", "64", "--quiet-s", "2", "--json"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    figures = json.loads(result.output.strip().splitlines()[-1])
    assert figures["clients"] == 64 and figures["nodes"] >= 400
    assert figures["reclaims"] == 1 and figures["reclaim_ms"] > 0.0
    assert figures["leave_max_stall_ms"] >= 0.0 and figures["freeze_ms"] >= 0.0
    assert figures["reclaim_max_stall_ms"] >= 0.0


def test_fewer_clients_than_a_reclaim_needs_is_refused() -> None:
    result = CliRunner().invoke(main, ["--clients", "10"])
    assert result.exit_code == 2 and "at least 64" in result.output
