"""The captions benchmark (issue 41's 0.5 s bound, measured: bench/captions.py) runs briefly and
prints its JSON line with both screens' lateness."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from bench.captions import REQUIREMENT_MS, main

pytestmark = [pytest.mark.browser, pytest.mark.timeout(300)]


def test_bench_captions_smoke() -> None:
    result = CliRunner().invoke(main, ["--time-scale", "10", "--captions", "2", "--json"])
    assert result.exit_code == 0, result.output
    line = json.loads(result.output.strip().splitlines()[-1])
    assert {"time_scale", "captions", "late_ms", "requirement_ms", "within_requirement"} <= set(
        line
    )
    assert line["requirement_ms"] == REQUIREMENT_MS and line["time_scale"] == 10
    for screen in ("touch_screen", "phone"):
        assert line["captions"][screen] >= 1, line
        assert line["late_ms"][screen]["p50"] is not None, line
    print(line)
