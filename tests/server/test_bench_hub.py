"""`guidebot bench hub` end to end, briefly: the server, the robots and the GUIs in their own
processes over real WebSockets on loopback (picows clients), every state counted at every GUI."""

from __future__ import annotations

import json
from typing import Any

import pytest
from click.testing import CliRunner

from bench.hub import hub as bench_hub

pytestmark = pytest.mark.timeout(120)


def run(*args: str) -> dict[str, Any]:
    result = CliRunner().invoke(bench_hub, [*args, "--json"])
    assert result.exit_code == 0, result.output
    last: dict[str, Any] = json.loads(result.output.strip().splitlines()[-1])
    return last


def test_every_state_reaches_every_gui_of_the_hub_and_of_the_plain_broadcast() -> None:
    last = run("--robots", "20", "--rate", "5", "--guis", "2", "--seconds", "3", "--peer")
    assert last["listener"] == "picows"  # the hub's own listener (hub_ws_port) by default
    assert last["peer"]["server"] == "fastapi"
    for result in (last, last["peer"]):
        assert result["dropped"] == 0 and result["refused"] == 0
        assert result["msgs_in_per_s"] == pytest.approx(100, rel=0.05)  # 20 robots x 5 Hz
        assert result["msgs_out_per_s"] == 2 * result["msgs_in_per_s"]  # to each of 2 GUIs
        assert 0 < result["latency_ms"]["p50"] <= result["latency_ms"]["p99"]
    assert last["agree"] is True
    assert set(last["ratio"]) == {
        "latency_p50",
        "latency_p99",
        "server_cpu_percent",
        "frames_out_per_s",
    }


def test_the_picows_broadcast_is_the_peer_and_asgi_the_listener_on_request() -> None:
    last = run(
        *("--robots", "20", "--rate", "5", "--guis", "2", "--seconds", "3"),
        *("--peer", "--peer-server", "picows", "--listener", "asgi"),
    )
    assert last["listener"] == "asgi"  # the hub's clients on /ws through uvicorn
    assert last["dropped"] == 0 and last["msgs_out_per_s"] == 2 * last["msgs_in_per_s"] > 0
    peer = last["peer"]
    assert peer["server"] == "picows"
    assert peer["dropped"] == 0 and peer["msgs_out_per_s"] == 2 * peer["msgs_in_per_s"] > 0
    assert peer["msgs_per_frame"] == 1.0  # it sends each frame on as it came
    assert last["agree"] is True


def test_a_slow_gui_gets_the_newest_states_and_is_reported_apart() -> None:
    last = run(
        "--robots", "20", "--rate", "5", "--guis", "1", "--seconds", "3", "--slow-gui", "300"
    )
    assert last["dropped"] == 0  # the normal GUI got everything
    slow = last["slow_gui"]
    assert slow["read_delay_ms"] == 300
    # It reads about 3 frames a second: fewer frames than states, each robot's newest kept.
    assert slow["frames"] < slow["received"] + slow["superseded"]
