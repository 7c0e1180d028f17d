"""`guidebot bench petri` keeps working: a short run prints the agreed JSON line, and with
``--peer`` runs SNAKES on the same nets and checks the answers agree."""

from __future__ import annotations

import importlib.util
import json

import pytest
from click.testing import CliRunner

from bench.petri import SnakesNet, chain_net, ring_net
from guidebot.cli import main

SHORT = ["--samples", "20", "--instances", "20", "--chain", "200", "--laps", "20"]
SHORT += ["--rounds", "2", "--json"]
needs_snakes = pytest.mark.skipif(
    importlib.util.find_spec("snakes") is None, reason="SNAKES (extra 'peers') not installed"
)


def run(*args: str) -> dict[str, object]:
    result = CliRunner().invoke(main, ["bench", "petri", *args])
    assert result.exit_code == 0, result.output
    parsed: dict[str, object] = json.loads(result.output.strip().splitlines()[-1])
    return parsed


def test_bench_petri_prints_its_result_line() -> None:
    result = run(*SHORT)
    assert list(result) == [
        "start_ms",
        "firings_per_s",
        "ring_firings_per_s",
        "monitor_cost",
        "instances",
        "rss_mb_per_1000_instances",
        "rounds",
        "compile_ms",
        "load_ms",
    ]
    ring = result["ring_firings_per_s"]
    assert isinstance(ring, dict) and set(ring) == {"monitored", "unmonitored"}
    assert isinstance(result["monitor_cost"], float) and result["monitor_cost"] > 0


@needs_snakes
def test_bench_petri_peer_runs_snakes_side_by_side() -> None:
    result = run(*SHORT, "--peer", "--peer-size", "300")
    peer, ratio = result["peer"], result["ratio"]
    assert isinstance(peer, dict) and isinstance(ratio, dict)
    assert peer["library"].startswith("SNAKES ") and peer["answers_equal"] is True
    assert set(ratio) == {"firings_per_s", "ring_firings_per_s"}
    assert all(value > 0 for value in ratio.values())


@needs_snakes
def test_the_snakes_peer_computes_what_our_engine_computes() -> None:
    # the answer check is only worth something if it can disagree: a chain ends at its end,
    # a ring after its laps, and SNAKES says so with the same counts
    assert SnakesNet(chain_net(30)).run() == (30, {"p30": 1})
    assert SnakesNet(ring_net(5, 3)).run() == (15, {"r0": 1})
