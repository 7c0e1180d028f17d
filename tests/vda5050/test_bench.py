"""``guidebot bench vda5050`` runs end to end on a small fleet and prints its JSON line."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from bench.vda5050 import main
from guidebot.demo_vda import mosquitto_binary

pytestmark = pytest.mark.timeout(120)


def test_the_bench_measures_states_and_grants() -> None:
    if mosquitto_binary() is None:
        pytest.skip("mosquitto is not installed: run `make system-deps` (Debian mosquitto)")
    result = CliRunner().invoke(
        main,
        ["--robots", "5", "--movers", "2", "--guidebot", "2", "--seconds", "4", "--json"],
        catch_exceptions=False,
    )
    assert result.exit_code == 0, result.output
    figures = json.loads(result.output.strip().splitlines()[-1])
    assert figures["robots"] == 5 and figures["states"] > 0 and figures["refused"] == 0
    assert figures["state_to_hub_ms"]["p50"] > 0
    assert figures["grants"] > 0 and figures["grant_to_order_ms"]["p50"] > 0
    assert figures["server_cpu_percent"] > 0
    assert figures["guidebot"] == 2 and figures["guidebot_states"] > 0
    assert figures["guidebot_state_to_hub_ms"]["p50"] > 0
    assert figures["state_ratio"]["p50"] is not None
