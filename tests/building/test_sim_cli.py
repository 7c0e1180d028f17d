"""building_sim as a process: the CLI, its control API, Modbus answers and scenarios."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path

import httpx
import pytest
import yaml
from click.testing import CliRunner

from backend.building._modbus import ModuleClient, ModuleExceptionAnswer
from building_sim.cli import building_sim
from building_sim.scenario import ScenarioError, load_scenario, run_scenario
from building_sim.simulator import BuildingSimulator
from guidebot.site.building import PointKind
from guidebot.site.building_config import load_building
from guidebot.testing import wait_until

from .conftest import site_dict

DEMO_SITE = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"


async def test_cli_serves_the_site_and_press_works_through_the_control_api() -> None:
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "building_sim",
        "--site",
        str(DEMO_SITE),
        "--port-zero",
        "--control-port",
        "0",
        "--time-scale",
        "10",
        stdout=asyncio.subprocess.PIPE,
    )
    try:
        assert process.stdout is not None
        ready = json.loads(await asyncio.wait_for(process.stdout.readline(), 30))
        assert ready["ready"] is True
        assert set(ready["modules"]) == {"otb_ground", "otb_first"}
        # `guidebot building-sim press` against the running process.
        runner = CliRunner()
        result = await asyncio.to_thread(
            runner.invoke,
            building_sim,
            ["press", "button_entrance", "--ms", "5000", "--url", ready["control"]],
        )
        assert result.exit_code == 0, result.output
        client = ModuleClient("127.0.0.1", ready["modules"]["otb_ground"], unit_id=1, timeout_s=2)
        await client.connect()
        try:
            # button_entrance is discrete input 1 of otb_ground in the demo site.
            assert await client.read(PointKind.discrete_input, 1, 1) == [1]
        finally:
            client.close()
        async with httpx.AsyncClient(base_url=ready["control"]) as http:
            state = (await http.get("/state")).json()
            assert state["buttons"]["button_entrance"] is True
            missing = await http.post("/buttons/nope/press", json={"ms": 100})
            assert missing.status_code == 404
            assert "no button 'nope'" in missing.json()["detail"]
    finally:
        process.terminate()
        assert await asyncio.wait_for(process.wait(), 20) == 0


def test_cli_refuses_a_site_with_a_bad_address(tmp_path: Path) -> None:
    site = site_dict()
    site["building"]["modules"][0]["points"][1]["address"] = 0  # d1_open on b1's address
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(site), encoding="utf-8")
    result = CliRunner().invoke(building_sim, ["--site", str(path)])
    assert result.exit_code != 0
    assert "point 'd1_open' has address 0, already used by 'b1'" in result.output


def test_press_without_a_running_simulator_says_so() -> None:
    result = CliRunner().invoke(building_sim, ["press", "B1", "--url", "http://127.0.0.1:9"])
    assert result.exit_code != 0
    assert "not reachable" in result.output


async def test_modbus_answers_like_a_module() -> None:
    config = load_building(site_dict())
    async with BuildingSimulator(config, time_scale=20, port_zero=True) as sim:
        client = ModuleClient("127.0.0.1", sim.ports["M1"], unit_id=1, timeout_s=2)
        await client.connect()
        try:
            await client.write(PointKind.coil, 1, 1)  # D1's open coil
            await wait_until(lambda: sim.doors["D1"].state == "open")
            assert await client.read(PointKind.discrete_input, 1, 1) == [1]
            assert await client.read(PointKind.coil, 1, 1) == [1]
            # Reading past the module's table is an exception answer, as on a real module.
            with pytest.raises(ModuleExceptionAnswer, match=r"exception 2 \(illegal data address"):
                await client.read(PointKind.discrete_input, 100, 1)
        finally:
            client.close()


async def test_scenario_plays_timed_presses_and_faults(tmp_path: Path) -> None:
    config = load_building(site_dict())
    path = tmp_path / "demo.yaml"
    path.write_text(
        yaml.safe_dump(
            [
                {"at": 0.0, "press": "B1", "ms": 2000},
                {"at": 1.0, "fault": "M2", "kind": "offline"},
            ]
        ),
        encoding="utf-8",
    )
    async with BuildingSimulator(config, time_scale=20, port_zero=True) as sim:
        steps = load_scenario(path, sim)
        assert await run_scenario(sim, steps) == 2
        assert sim.state()["buttons"]["B1"] is True
        assert sim.servers["M2"].online is False
        bad = tmp_path / "bad.yaml"
        bad.write_text(yaml.safe_dump([{"at": 0, "press": "B9"}]), encoding="utf-8")
        with pytest.raises(ScenarioError, match="no button 'B9'"):
            load_scenario(bad, sim)
