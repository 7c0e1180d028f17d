"""docker-compose.yml's "cluster" profile, for real: two servers on PostgreSQL and Redis behind
nginx on a private Docker engine, and a fail-over through the proxy (docs/scaling.md).

The engine, the project image and the offline build are those of tests/test_compose_engine.py
(tests/compose_engine.py). The containers here reach no registry, so the official images the
profile names (postgres:16, redis:7, nginx:1.27-alpine) are stand-ins built from Debian
bookworm's packages (a second debootstrap base, cached in .cache/) and tagged with those names:
tests/compose_standins/ gives each the contract docker-compose.yml uses (POSTGRES_* variables,
pg_isready, redis-cli, the mounted nginx.conf). docker-compose.yml itself runs unchanged, on its
own bridge network, with the proxy published on 127.0.0.1:GUIDEBOT_CLUSTER_PORT (Docker's
userland proxy: the engine runs without iptables).

`docker compose --profile cluster up -d --build proxy` (the file's documented command) starts
the proxy and what it needs; through the proxy both servers answer /api/health and name the same
leader, exactly one leads, the follower itself answers REST with 503 naming the leader, and REST
through the proxy (tasks created, the task list) reaches the leader whichever server nginx tries
first. `docker compose kill` of the leader (SIGKILL; Docker does not restart a container killed
this way): within 15 s the other server leads through the proxy, the tasks created before are
still listed and new REST calls work (the dead server's address answers nothing:
deploy/cluster/nginx.conf's proxy_connect_timeout keeps nginx from waiting 60 s on it). Started
again, the old leader comes back as a follower. `docker compose down -v` leaves no container and
no volume. About 2.5 minutes with the debootstrap tarballs cached; the first run downloads
Debian's packages.
"""

from __future__ import annotations

import json
import time
import uuid
from typing import Any

import httpx
import pytest
from compose_engine import (
    OFFLINE_BUILD,
    ROOT,
    assert_nothing_left,
    down,
    prepare,
    run,
    wait,
)
from netports import free_ports

ADMIN = {"Authorization": "Bearer dev-admin-token"}
SERVERS = {"server-a", "server-b"}
FAIL_OVER_S = 15.0
ASK_TASKS = (
    "import httpx; r = httpx.get('http://127.0.0.1:8000/api/tasks',"
    " headers={'Authorization': 'Bearer dev-admin-token'}); print(r.status_code, r.text)"
)

pytestmark = [pytest.mark.docker, pytest.mark.timeout(1200)]


def _cluster_reports(http: httpx.Client) -> dict[str, dict[str, Any]]:
    """Every server's /api/health "cluster" section, by process name, as seen through the proxy
    (which spreads requests over the servers: ask until both answered)."""
    reports: dict[str, dict[str, Any]] = {}

    def both() -> bool:
        reply = http.get("/api/health")
        if reply.status_code == 200:
            cluster = reply.json()["cluster"]
            reports[cluster["process"]] = cluster
        return set(reports) == SERVERS

    wait(both, 30, f"both servers answering /api/health through the proxy (seen: {reports})")
    return reports


def _create_task(http: httpx.Client) -> str:
    reply = http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}})
    assert reply.status_code == 201, reply.text
    task_id: str = reply.json()["id"]
    return task_id


def _listed_ids(http: httpx.Client) -> set[str]:
    reply = http.get("/api/tasks")
    assert reply.status_code == 200, reply.text
    return {task["id"] for task in reply.json()["tasks"]}


def test_cluster_profile_serves_through_the_proxy_and_fails_over(engine: dict[str, str]) -> None:
    prepare(engine, standins=True)
    (port,) = free_ports(1)
    project = f"guidebot-cluster-{uuid.uuid4().hex[:6]}"
    env = {
        **engine,
        "COMPOSE_PROJECT_NAME": project,
        **OFFLINE_BUILD,
        "GUIDEBOT_CLUSTER_PORT": str(port),
    }
    compose = ["docker", "compose", "-f", str(ROOT / "docker-compose.yml"), "--profile", "cluster"]
    try:
        run([*compose, "up", "-d", "--build", "proxy"], env, timeout=900)
        running = set(run([*compose, "ps", "--services", "--status", "running"], env).split())
        assert running == {"postgres", "redis", "server-a", "server-b", "proxy"}
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", headers=ADMIN, timeout=10) as http:
            wait(lambda: http.get("/api/health").status_code == 200, 60, "the proxy answers")
            reports = _cluster_reports(http)
            leaders = [name for name, report in reports.items() if report["leading"]]
            assert len(leaders) == 1, reports
            (leader,) = leaders
            assert {report["leader"] for report in reports.values()} == {leader}
            wait(lambda: _cluster_reports(http)[leader]["serving"], 30, "the leader serving")
            for report in reports.values():
                assert report["broker"]["connected"], report
            # REST runs on the leader only (asked inside the follower's container: only the
            # proxy is published) ...
            (follower,) = SERVERS - {leader}
            direct = run([*compose, "exec", "-T", follower, "python", "-c", ASK_TASKS], env)
            status, named = direct.split(maxsplit=1)
            assert (status, json.loads(named)["leader"]) == ("503", leader), direct
            # ... and nginx sends a follower's 503 on to the next server, so every call through
            # the proxy works, whichever server it tried first.
            created = [_create_task(http) for _ in range(3)]
            for _ in range(3):
                assert set(created) <= _listed_ids(http)

            killed = time.monotonic()
            run([*compose, "kill", leader], env)

            def follower_leads() -> bool:
                reply = http.get("/api/health")
                cluster = reply.json().get("cluster", {}) if reply.status_code == 200 else {}
                return bool(
                    cluster.get("process") == follower
                    and cluster.get("leading")
                    and cluster.get("serving")
                )

            wait(follower_leads, FAIL_OVER_S, f"{follower} leading after {leader} was killed")
            took = time.monotonic() - killed
            print(f"fail-over from {leader} to {follower} seen through the proxy in {took:.1f} s")
            # The tasks the old leader acknowledged are in PostgreSQL; the new one serves REST.
            wait(lambda: http.get("/api/tasks").status_code == 200, 10, "REST after fail-over")
            assert set(created) <= _listed_ids(http)
            assert _create_task(http) in _listed_ids(http)
            # The old leader, started again, comes back as a follower of the new one.
            run([*compose, "start", leader], env)
            wait(
                lambda: (
                    (report := _cluster_reports(http)[leader])["leader"] == follower
                    and not report["leading"]
                ),
                60,
                f"{leader} back as a follower of {follower}",
            )
            assert _create_task(http) in _listed_ids(http)
    finally:
        status = down(compose, env, 30, 8000)
    assert status == 0
    assert_nothing_left(project, engine)
    volumes = run(
        ["docker", "volume", "ls", "-q", "--filter", f"label=com.docker.compose.project={project}"],
        engine,
    )
    assert volumes.strip() == "", f"volumes left: {volumes}"
