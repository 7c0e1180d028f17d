"""The console benchmark runs briefly and prints its JSON line with the issue's keys."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from bench.console import main

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


def test_bench_console_smoke() -> None:
    result = CliRunner().invoke(main, ["--robots", "4", "--rate", "5", "--seconds", "2", "--json"])
    assert result.exit_code == 0, result.output
    line = json.loads(result.output.strip().splitlines()[-1])
    keys = {"robots", "rate_hz", "state_to_screen_ms", "dropped_frames_percent", "page_heap_mb"}
    assert keys <= line.keys()
    assert line["robots"] == 4 and line["states_drawn"] > 0
    assert line["state_to_screen_ms"]["p50"] is not None
