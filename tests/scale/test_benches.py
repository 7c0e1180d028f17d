"""The scale-out benchmarks, briefly (docs/scaling.md): `guidebot bench failover` (kills and
pauses of the leader) and `guidebot bench hub --servers 2` report the keys issue 17 names."""

from __future__ import annotations

import json

import orjson
import pytest
from click.testing import CliRunner

from bench.failover import main as bench_failover
from bench.hub import hub as bench_hub
from bench.hub_workers import _state_frame
from guidebot.messages import Message
from guidebot.wire import encode
from tests.server.postgres import PostgresServer

from .redis import RedisServer


@pytest.mark.parametrize("mode", ["kill", "pause"])
def test_bench_failover_reports_the_issue_keys(
    redis: RedisServer, postgres: PostgresServer, mode: str
) -> None:
    args = ["--db", postgres.database(), "--broker", redis.url, "--kills", "1", "--tasks", "3"]
    args += ["--json", *(["--pause"] if mode == "pause" else [])]
    result = CliRunner().invoke(bench_failover, args)
    assert result.exit_code == 0, result.output
    last = json.loads(result.output.strip().splitlines()[-1])
    assert set(last) >= {"leader_kill_to_new_leader_ms", "tasks_lost", "double_grants"}
    assert last["kills"] == 1 and last["mode"] == mode
    assert 0 < last["leader_kill_to_new_leader_ms"]["max"] < 15_000
    assert last["tasks_lost"] == 0
    assert last["double_grants"] == 0


def test_bench_hub_over_two_servers_reports_cross_process_latency(
    redis: RedisServer, postgres: PostgresServer
) -> None:
    args = ["--servers", "2", "--robots", "10", "--rate", "5", "--guis", "2", "--seconds", "3"]
    args += ["--db", postgres.database(), "--broker", redis.url, "--json"]
    result = CliRunner().invoke(bench_hub, args)
    assert result.exit_code == 0, result.output
    last = json.loads(result.output.strip().splitlines()[-1])
    assert last["servers"] == 2 and last["dropped"] == 0 and last["refused"] == 0
    assert last["latency_samples"]["cross"] > 0 and last["latency_samples"]["local"] > 0
    assert last["cross_process_latency_ms"]["p50"] > 0
    assert len(last["server_cpu_percent_each"]) == 2


def test_bench_hub_servers_needs_a_database_and_a_broker() -> None:
    result = CliRunner().invoke(bench_hub, ["--servers", "2", "--json"])
    assert result.exit_code == 2
    assert "--servers needs --db" in result.output


def test_bench_robots_send_states_as_hub_client_does() -> None:
    """The bench builds robot_state frames without the model (its CPU is the server's
    competitor): they must be the frames a robot's HubClient sends, field for field."""
    sent = orjson.loads(_state_frame("R7", 3))
    model = Message(type="robot_state", source="R7", payload=sent["payload"])
    expected = orjson.loads(encode(model))
    assert list(sent) == list(expected)
    assert {k: v for k, v in sent.items() if k not in ("id", "timestamp")} == {
        k: v for k, v in expected.items() if k not in ("id", "timestamp")
    }
    assert Message.model_validate(sent).payload["seq"] == 3
    assert sent["id"] != orjson.loads(_state_frame("R7", 4))["id"]
