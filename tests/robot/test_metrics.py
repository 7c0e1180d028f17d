"""A robot's GET /metrics on its touch-screen port: CAN counters, modules, losses, loop lag."""

from __future__ import annotations

import asyncio
import uuid

import httpx
from prometheus_client.parser import text_string_to_metric_families

from robot_agent.agent import AgentConfig, RobotAgent
from tests.promtool import promtool_accepts


def values(text: str) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    return {
        (s.name, tuple(sorted(s.labels.items()))): s.value
        for family in text_string_to_metric_families(text)
        for s in family.samples
    }


async def scrape(http: httpx.AsyncClient) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    reply = await http.get("/metrics")
    assert reply.status_code == 200
    await promtool_accepts(reply.text)
    return values(reply.text)


async def test_robot_metrics_count_frames_and_a_module_loss() -> None:
    config = AgentConfig(
        name="R1",
        can=f"virtual:m-{uuid.uuid4().hex[:8]}",
        gui_port=0,
        speech_engine=None,
        start_node="hall",
    )
    async with RobotAgent(config) as agent:
        await agent.hardware.stack.wait_online(timeout=30)  # type: ignore[union-attr]
        assert agent.screen_server is not None
        async with httpx.AsyncClient(base_url=agent.screen_server.url, timeout=10) as http:
            first = await scrape(http)
            assert first[("guidebot_can_frames_total", (("kind", "frames_rx"),))] > 0
            online = first[("guidebot_can_modules", (("state", "online"),))]
            assert online >= 5
            assert first[("guidebot_can_module_losses_total", ())] == 0

            # A sonar ring (0x20) goes away: the master's time-out reports it lost.
            agent.bus.endpoint("operator").publish(
                "module_plug", {"module_id": 0x20, "plugged": False}
            )
            for _ in range(200):
                later = await scrape(http)
                lag_seen = later[("guidebot_robot_loop_lag_seconds_count", ())] >= 1
                if later[("guidebot_can_module_losses_total", ())] == 1 and lag_seen:
                    break
                await asyncio.sleep(0.05)
            assert later[("guidebot_can_module_losses_total", ())] == 1
            assert later[("guidebot_can_modules", (("state", "online"),))] == online - 1
            # Load since the previous scrape: watchdog frames keep it above 0 once a scrape
            # window holds one (an idle, enabled robot may send none within 50 ms).
            for _ in range(100):
                load = (await scrape(http))[("guidebot_can_bus_load_ratio", ())]
                if load > 0:
                    break
                await asyncio.sleep(0.05)
            assert 0 < load < 1
            assert later[("guidebot_robot_loop_lag_seconds_count", ())] >= 1
