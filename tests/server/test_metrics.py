"""GET /metrics on a real server: who may read it, and the reaction chain fed by a live button
press on building_sim (a WebSocket client plays the robot and reports its half)."""

from __future__ import annotations

import asyncio
import json
import re
import time
from pathlib import Path

import httpx
import yaml
from prometheus_client.parser import text_string_to_metric_families

from backend.auth import Role
from backend.hub import Hub
from backend.metrics.server import ServerMetrics
from backend.settings import Settings, StaticToken
from backend.state import AppState
from backend.testing import running_server
from bench.reaction import bench_site
from building_sim.simulator import BuildingSimulator
from guidebot.client import HubClient
from guidebot.messages import Message
from guidebot.site.building_config import load_building
from tests.promtool import promtool_accepts

PANEL = "panel-token-1234"
OPERATOR = "operator-token-1234"
METRICS = "metrics-token-1234"


def samples(text: str) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    return {
        (s.name, tuple(sorted(s.labels.items()))): s.value
        for family in text_string_to_metric_families(text)
        for s in family.samples
    }


async def test_metrics_of_a_live_button_press(tmp_path: Path) -> None:
    data = bench_site(1, 50, 0)
    async with BuildingSimulator(load_building(data), time_scale=1, port_zero=True) as sim:
        data["modules"][0]["port"] = sim.ports["otb"]
        site = tmp_path / "site.yaml"
        site.write_text(yaml.safe_dump(data))
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db",
            site=site,
            metrics_token=METRICS,
            tokens=[
                StaticToken(token=PANEL, name="panel-1", role=Role.PANEL),
                StaticToken(token=OPERATOR, name="op-1", role=Role.OPERATOR),
            ],
        )
        async with running_server(settings) as server:
            robot = HubClient(server.ws_url, "robot-R1-bench-token")
            admin = HubClient(server.ws_url, server.admin_token)
            measured: asyncio.Queue[Message] = asyncio.Queue()
            admin.subscribe("reaction_measured", measured.put_nowait)

            def on_task(message: Message) -> None:
                task_id = message.payload["task_id"]
                robot.publish("task_started", {"task_id": task_id, "robot": "R1"})
                now = time.time()
                stamps = {"received_at": now, "net_started_at": now + 0.001}
                stamps |= {"path_requested_at": now + 0.002, "path_received_at": now + 0.004}
                stamps |= {"commanded_at": now + 0.005, "moving_at": now + 0.006}
                robot.publish("task_reaction", {"task_id": task_id, "robot": "R1", **stamps})

            robot.subscribe("task_assigned", on_task)
            await robot.start()
            await admin.start()
            try:
                await admin.sync()
                robot.publish(
                    "robot_state", {"robot": "R1", "node": "c1", "mode": "idle", "battery": 1.0}
                )
                building = server.app.state.building
                for _ in range(1000):
                    robots = server.app.state.task_manager.robots
                    polled = all(p.health.polls > 0 for p in building.pollers.values())
                    if polled and robots["R1"].online and robots["R1"].node == "c1":
                        break
                    await asyncio.sleep(0.02)

                pressed = time.time()
                sim.press("button_west", 500)
                report = await asyncio.wait_for(measured.get(), 20)
            finally:
                await robot.close()
                await admin.close()

            assert report.payload["button"] == "button_west"
            assert report.payload["robot"] == "R1"
            stamps = report.payload["stamps"]
            assert pressed <= stamps["sampled_at"] <= stamps["input_published_at"]
            assert stamps["input_published_at"] <= stamps["assigned_at"] <= stamps["moving_at"]
            steps = report.payload["steps_ms"]
            assert 195 <= steps["filter"] <= 400  # 200 ms from the first changed sample
            assert set(steps) >= {"task_manager", "link", "get_path", "can"}

            async with httpx.AsyncClient(base_url=server.url) as http:
                assert (await http.get("/metrics")).status_code == 401
                bad = await http.get("/metrics", headers={"Authorization": "Bearer wrong-token"})
                assert bad.status_code == 401
                panel = await http.get("/metrics", headers={"Authorization": f"Bearer {PANEL}"})
                assert panel.status_code == 403 and "metrics token" in panel.json()["detail"]
                ok = await http.get("/metrics", headers={"Authorization": f"Bearer {OPERATOR}"})
                assert ok.status_code == 200
                assert ok.headers["content-type"].startswith("text/plain")
                by_token = await http.get(
                    "/metrics", headers={"Authorization": f"Bearer {METRICS}"}
                )
                assert by_token.status_code == 200
            await promtool_accepts(by_token.text)
            values = samples(by_token.text)
            assert values[("guidebot_reaction_step_seconds_count", (("step", "filter"),))] == 1
            assert values[("guidebot_reaction_step_seconds_count", (("step", "can"),))] == 1
            assert values[("guidebot_reaction_seconds_count", ())] == 1
            assert values[("guidebot_task_wait_seconds_count", ())] == 1
            assert values[("guidebot_task_assignment_seconds_count", ())] == 1
            assert values[("guidebot_hub_messages_in_total", (("type", "task_reaction"),))] == 1
            assert values[("guidebot_modbus_polls_total", (("module", "otb"),))] > 0
            assert values[("guidebot_modbus_poll_period_seconds", (("module", "otb"),))] == 0.05
            assert values[("guidebot_modbus_online", (("module", "otb"),))] == 1
            jitter = (("module", "otb"), ("percentile", "99"))
            assert values[("guidebot_modbus_poll_jitter_seconds", jitter)] >= 0
            assert values[("guidebot_tasks", (("state", "running"),))] == 1
            assert values[("guidebot_hub_delivery_latency_seconds_count", ())] > 0
            # Docs are the contract: every family the server exposes is in docs/metrics.md.
            documented = DOCS.read_text(encoding="utf-8")
            for family in text_string_to_metric_families(by_token.text):
                if family.name.startswith("guidebot_") and not family.name.endswith("_created"):
                    assert family.name in documented, family.name


DOCS = Path(__file__).resolve().parents[2] / "docs" / "metrics.md"
DASHBOARD = DOCS.with_name("grafana-dashboard.json")


def test_dashboard_queries_only_documented_metrics() -> None:
    documented = DOCS.read_text(encoding="utf-8")
    dashboard = json.loads(DASHBOARD.read_text(encoding="utf-8"))
    names = set()
    for panel in dashboard["panels"]:
        for target in panel["targets"]:
            names |= set(re.findall(r"guidebot_[a-z_]+", target["expr"]))
    assert names
    for name in names:
        base = re.sub(r"_(bucket|total|count|sum)$", "", name)
        assert base in documented, name


def test_lock_waits_are_per_area_and_only_the_reply_counts() -> None:
    hub = Hub(gc_freeze=False)
    metrics = ServerMetrics(AppState({"hub": hub}))
    asked = Message(type="request_area", source="R1", payload={"robot": "R1", "area": "corridor"})
    asked.timestamp = 100.0
    metrics.observe(asked)
    broadcast = Message(type="area_granted", payload={"robot": "R1", "area": "corridor"})
    metrics.observe(broadcast)  # everyone's copy: no correlation, not counted
    reply = Message(
        type="area_granted",
        destination="R1",
        correlation_id=asked.id,
        payload={"robot": "R1", "area": "corridor"},
    )
    reply.timestamp = 102.5
    metrics.observe(reply)
    metrics.observe(reply)  # a duplicate reply finds no open request
    values = samples(metrics.render().decode())
    assert values[("guidebot_lock_wait_seconds_count", (("area", "corridor"),))] == 1
    assert values[("guidebot_lock_wait_seconds_sum", (("area", "corridor"),))] == 2.5
    assert values[("guidebot_hub_messages_in_total", (("type", "area_granted"),))] == 3
    # No services yet (a server starting): the scrape still answers.
    assert ("guidebot_hub_clients", (("role", "robot"),)) in values
