"""A whole fleet on two server processes for the fail-over tests: the building simulator, alpha
and beta (`guidebot server --broker`, BuildingInterface on whichever leads) and robot agents
with simulated RoboCAN hardware, each its own process on loopback (bench/soak_fleet.py's
``Child``, bench/servers.py's ``ServerProcess``)."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import yaml

from bench.cluster_clients import ROBOT_TOKENS
from bench.servers import ADMIN_TOKEN, DEMO, ServerProcess, start_servers, wait_until
from bench.soak_fleet import Child, free_port
from bench.soak_site import with_ports

__all__ = ["AUTH", "ClusterFleet", "cluster_fleet"]

AUTH = {"Authorization": f"Bearer {ADMIN_TOKEN}"}


@dataclass
class ClusterFleet:
    servers: list[ServerProcess]
    building: Child
    site_file: Path
    work: Path
    time_scale: float
    robots: dict[str, Child] = field(default_factory=dict)

    def start_robot(self, name: str, server_url: str) -> Child:
        """A robot agent (simulated RoboCAN modules, a visitor who always answers yes) linked
        to ``server_url`` (a server process, or a relay in front of them)."""
        robot = Child(
            name,
            [
                *("robot", "--name", name, "--server", server_url, "--token", ROBOT_TOKENS[name]),
                *("--simulate", "--time-scale", f"{self.time_scale:g}"),
                *("--site", str(self.site_file), "--gui-port", str(free_port())),
                *("--visitor", "yes", "--state-period", "0.5", "--log-level", "warning"),
            ],
            self.work / f"{name}.log",
        )
        robot.start()
        self.robots[name] = robot
        return robot

    async def online(self, leader: ServerProcess, *names: str) -> None:
        """Wait until the leader's Task Manager sees ``names`` online."""

        async def all_online() -> bool:
            async with httpx.AsyncClient(headers=AUTH, timeout=5) as http:
                answer = await http.get(f"{leader.url}/api/robots")
            if answer.status_code != 200:
                return False
            return set(names) <= {r["name"] for r in answer.json() if r.get("online")}

        await wait_until(all_online, 60, f"{', '.join(names)} online on {leader.name}")


@contextlib.asynccontextmanager
async def cluster_fleet(
    db_url: str, broker_url: str, work: Path, *, time_scale: float = 10.0
) -> AsyncIterator[ClusterFleet]:
    """The demo museum's building and two servers on it (alpha leads); robots on demand."""
    building = Child(
        "building_sim",
        [
            *("building-sim", "--site", str(DEMO), "--time-scale", f"{time_scale:g}"),
            *("--port-zero", "--control-port", "0"),
        ],
        work / "building_sim.log",
    )
    building.start()
    fleet: ClusterFleet | None = None
    try:

        async def ready() -> dict[str, Any] | None:
            return building.ready_json()

        ports = (await wait_until(ready, 60, "the building simulator"))["modules"]
        site: dict[str, Any] = yaml.safe_load(DEMO.read_text(encoding="utf-8"))
        site_file = work / "site.yaml"
        site_file.write_text(yaml.safe_dump(with_ports(site, ports), sort_keys=False))
        env = {"GUIDEBOT_BUILDING_ENABLED": "true"}
        async with start_servers(
            ["alpha", "beta"], db_url, broker_url, work, site=site_file, env=env
        ) as servers:
            fleet = ClusterFleet(servers, building, site_file, work, time_scale)
            try:
                yield fleet
            finally:
                for robot in fleet.robots.values():
                    robot.stop()
    finally:
        building.stop()
