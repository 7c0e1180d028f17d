"""/api/health reports every component; a failed one makes the server "degraded"; production
refuses to start without its building; a broken site file is refused with its lines."""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
import pytest
import yaml
from click.testing import CliRunner

from backend.app import create_app
from backend.settings import Settings
from backend.testing import running_server
from building_sim.simulator import BuildingSimulator
from guidebot.cli import main
from guidebot.site.building_config import load_building

from .helpers import DEMO

COMPONENTS = {"hub", "database", "task_manager", "traffic_manager", "building_interface"}


async def _health(url: str) -> dict[str, object]:
    async with httpx.AsyncClient(base_url=url) as http:
        r = await http.get("/api/health")
    assert r.status_code == 200
    return dict(r.json())


def _site_with_ports(tmp_path: Path, ports: dict[str, int]) -> Path:
    data = yaml.safe_load(DEMO.read_text())
    for module in data["modules"]:
        module["port"] = ports[module["id"]]
    for robot in data["robots"]:  # production refuses the published demo tokens
        robot["token"] = f"{robot['name']}-a-real-secret-token"
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


async def test_health_lists_every_component_ok(tmp_path: Path) -> None:
    data = yaml.safe_load(DEMO.read_text())
    async with BuildingSimulator(load_building(data), port_zero=True) as sim:
        site = _site_with_ports(tmp_path, sim.ports)
        settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/g.db", site=site)
        async with running_server(settings) as server:
            for _ in range(100):
                health = await _health(server.url)
                if health["status"] == "ok":
                    break
                await asyncio.sleep(0.05)
            assert health["status"] == "ok", health
            components = health["components"]
            assert isinstance(components, dict) and set(components) == COMPONENTS
            assert all(c["state"] == "ok" for c in components.values()), components
            assert components["building_interface"]["detail"] == "2/2 modules online"
            # A module that stops answering degrades the building, hence the server.
            await sim.set_fault("otb_first", "offline")
            for _ in range(200):
                health = await _health(server.url)
                if health["status"] == "degraded":
                    break
                await asyncio.sleep(0.05)
            building = health["components"]["building_interface"]  # type: ignore[index]
            assert building["state"] == "degraded" and "otb_first offline" in building["detail"]


async def test_production_refuses_a_building_that_cannot_run(tmp_path: Path) -> None:
    site = _site_with_ports(tmp_path, {"otb_ground": 0, "otb_first": 15999})
    production = Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/p.db",
        site=site,
        environment="production",
        admin_token="a-real-secret-token",
    )
    app = create_app(production)
    with pytest.raises(RuntimeError, match="GUIDEBOT_ENVIRONMENT=production refuses") as info:
        async with app.router.lifespan_context(app):
            pass
    assert "module 'otb_ground': port 0 only suits a simulator" in str(info.value)
    # In development the same site runs, and health says what is wrong.
    development = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/d.db", site=site)
    async with running_server(development) as server:
        health = await _health(server.url)
    assert health["status"] == "degraded"
    building = health["components"]["building_interface"]  # type: ignore[index]
    assert building["state"] == "degraded" and "0/2 modules online" in building["detail"]


def test_server_refuses_a_broken_site_file_with_its_lines(tmp_path: Path) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text(
        DEMO.read_text()
        .replace("{a: gc2, b: gc3}", "{a: gc2, b: nowhere}")
        .replace(
            "door_hall_open, address: 2, kind: coil",
            "door_hall_open, address: 9, kind: holding_register",
        )
    )
    result = CliRunner().invoke(main, ["server", "--site", str(broken), "--port", "0"])
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    lines = result.output.strip().splitlines()
    assert any(
        line.startswith(f"{broken}:")
        and "door open otb_ground/door_hall_open is a holding_register; it must be a coil" in line
        for line in lines
    ), result.output
    assert any("edges[16].b: unknown node 'nowhere'" in line for line in lines)
    assert lines[-1].endswith("2 problem(s): site refused, server not started")
