"""Fault injection on a simulated robot's screen port (robot_agent/sim_control.py): a CAN
module unplugged and replugged, the battery emptied; absent without simulated RoboCAN."""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import Callable

import httpx
import pytest

from guidebot.messages import Message
from robot_agent.agent import AgentConfig, RobotAgent

pytestmark = pytest.mark.timeout(60)


class Seen(list[Message]):
    """Every on-board message, with an event to wait on."""

    def __init__(self) -> None:
        super().__init__()
        self.changed = asyncio.Event()

    def __call__(self, message: Message) -> None:
        self.append(message)
        self.changed.set()

    async def until(self, predicate: Callable[[], object], timeout: float = 20.0) -> None:
        async with asyncio.timeout(timeout):
            while not predicate():
                self.changed.clear()
                await self.changed.wait()


async def test_unplug_replug_and_battery_panic_from_outside() -> None:
    config = AgentConfig(
        name="R1",
        can=f"virtual:R1-{uuid.uuid4().hex[:8]}",
        simulate=True,
        time_scale=10.0,
        gui_port=0,
        speech_engine=None,
        idle_net=None,
    )
    seen = Seen()
    async with RobotAgent(config) as agent:
        agent.bus.endpoint("test").subscribe("*", seen, tap=True)
        assert agent.screen_server is not None

        def status(module: int) -> list[str]:
            return [
                str(m.payload.get("state"))
                for m in seen
                if m.type == "module_status" and m.payload.get("module_id") == module
            ]

        async with httpx.AsyncClient(base_url=agent.screen_server.url) as http:
            r = await http.post("/sim/module_plug", json={"module_id": 0x10, "plugged": False})
            assert r.status_code == 202, r.text
            await seen.until(lambda: "lost" in status(0x10) or "offline" in status(0x10))
            r = await http.post("/sim/module_plug", json={"module_id": 0x10, "plugged": True})
            assert r.status_code == 202, r.text
            await seen.until(lambda: status(0x10)[-1:] == ["online"])
            unknown = await http.post(
                "/sim/module_plug", json={"module_id": 0x66, "plugged": False}
            )
            assert unknown.status_code == 404 and "0x66" in unknown.text
            bad = await http.post("/sim/battery", json={"level": 3})
            assert bad.status_code == 422
            r = await http.post("/sim/battery", json={"level": 0.05})
            assert r.status_code == 202, r.text
            await seen.until(lambda: any(m.type == "battery_panic" for m in seen))


async def test_no_fault_injection_without_simulated_robocan() -> None:
    config = AgentConfig(name="R1", can=None, gui_port=0, speech_engine=None, idle_net=None)
    async with RobotAgent(config) as agent:
        assert agent.screen_server is not None
        async with httpx.AsyncClient(base_url=agent.screen_server.url) as http:
            r = await http.post("/sim/battery", json={"level": 0.05})
    assert r.status_code in (404, 405)
