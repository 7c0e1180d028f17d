"""A VDA 5050 vehicle in the console (issue 37, docs/vda5050.md): the demo museum with GuideBot
robot R1 and simulated vehicle V1 on a real Mosquitto; V1 is on the map and in the Robots view
with its state, and staff pause it from its card and let it go on (``startPause`` /
``stopPause`` reach the vehicle; the card says paused meanwhile)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from playwright.async_api import expect

from guidebot.site.schema import Site
from guidebot.testing import wait_until
from guidebot.vda5050.sim import SimVehicle
from guidebot.vda5050.topics import Vehicle, parse_broker
from tests.vda5050.broker import mosquitto

pytestmark = [pytest.mark.browser, pytest.mark.timeout(150)]

V1 = Vehicle(manufacturer="GuideBotSim", serial_number="V1-0001")


def with_v1(data: dict[str, Any]) -> None:
    data["robots"].append(
        {
            "name": "V1",
            "token": "robot-V1-demo-token",
            "start_node": "entrance",
            "interface": "vda5050",
            "manufacturer": V1.manufacturer,
            "serial_number": V1.serial_number,
        }
    )


async def test_a_vda_vehicle_on_the_map_and_in_the_robots_view_paused_and_let_go_on(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Site
) -> None:
    entrance = next(n for n in demo_site.nodes if n.id == "entrance")
    with mosquitto() as broker:
        sim = SimVehicle(
            parse_broker(broker.url),
            V1,
            x=entrance.x,
            y=entrance.y,
            map_id=entrance.floor,
            node=entrance.id,
            time_scale=5.0,
            state_period_s=0.5,
        )
        async with fleet_factory(robots=1, edit=with_v1, mqtt_url=broker.url) as fleet, sim:
            watch = await open_page(fleet.admin_url)
            page = watch.page
            await web.sign_in(watch, web.operator_token)
            marker = page.get_by_role("button", name="robot V1")
            await expect(marker).to_be_visible(timeout=20_000)
            await expect(marker).to_have_attribute("title", "V1: idle, battery 100 %")
            await web.open_view(page, "Robots")
            card = page.get_by_role("region", name="V1")
            await expect(card.get_by_role("heading", name="V1")).to_contain_text("online")
            await expect(card).to_contain_text("near Welcome hall, Ground floor")
            await expect(card).to_contain_text("Modeidle")
            r1 = page.get_by_role("region", name="R1")
            await expect(r1.get_by_role("button", name="Send R1 to charge")).to_be_visible()
            await expect(r1.get_by_role("button", name="Pause R1")).to_have_count(0)

            await card.get_by_role("button", name="Pause V1").click()
            await wait_until(lambda: sim.paused, 20)
            await expect(card.get_by_role("heading", name="V1")).to_contain_text("paused")
            go_on = card.get_by_role("button", name="Let V1 go on")
            await expect(go_on).to_be_visible()
            await web.axe_check(page)
            await web.screenshot(page, "console-vda5050-paused")
            await go_on.click()
            await wait_until(lambda: not sim.paused, 20)
            await expect(card.get_by_role("heading", name="V1")).not_to_contain_text("paused")
            await expect(card.get_by_role("button", name="Pause V1")).to_be_visible()
            kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
            assert [k for k in kinds if k.endswith("Pause")] == ["startPause", "stopPause"]
            headers = {"Authorization": f"Bearer {fleet.server.admin_token}"}
            async with httpx.AsyncClient(base_url=fleet.server.url, headers=headers) as http:
                reply = await http.get("/api/events", params={"kind": "robot_paused"})
            assert [e["data"] for e in reply.json()["events"]] == [{"robot": "V1", "by": "desk"}]


async def test_a_hibernating_vehicle_is_shown_asleep_not_lost(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Site
) -> None:
    """A VDA 5050 3.0.0 vehicle sent to sleep (``POST /api/robots/V1/hibernate``): its card
    says hibernating (not lost), its mode offline, hibernating; woken, online again."""
    entrance = next(n for n in demo_site.nodes if n.id == "entrance")
    v3 = Vehicle(V1.manufacturer, V1.serial_number, version="3.0.0")

    def with_v1_v3(data: dict[str, Any]) -> None:
        with_v1(data)
        data["robots"][-1]["vda_version"] = "3.0.0"

    with mosquitto() as broker:
        sim = SimVehicle(
            parse_broker(broker.url),
            v3,
            x=entrance.x,
            y=entrance.y,
            map_id=entrance.floor,
            node=entrance.id,
            time_scale=5.0,
            state_period_s=0.5,
        )
        async with fleet_factory(robots=1, edit=with_v1_v3, mqtt_url=broker.url) as fleet, sim:
            watch = await open_page(fleet.admin_url)
            page = watch.page
            await web.sign_in(watch, web.operator_token)
            await web.open_view(page, "Robots")
            card = page.get_by_role("region", name="V1")
            heading = card.get_by_role("heading", name="V1")
            await expect(heading).to_contain_text("online", timeout=20_000)
            headers = {"Authorization": f"Bearer {fleet.server.admin_token}"}
            async with httpx.AsyncClient(base_url=fleet.server.url, headers=headers) as http:
                asleep = await http.post("/api/robots/V1/hibernate", json={"hibernating": True})
                assert asleep.status_code == 200, asleep.text
                await wait_until(lambda: sim.hibernating, 20)
                await expect(heading).to_contain_text("hibernating")
                await expect(heading).not_to_contain_text("lost")
                await expect(card).to_contain_text("Modeoffline, hibernating")
                await web.axe_check(page)
                awake = await http.post("/api/robots/V1/hibernate", json={"hibernating": False})
                assert awake.status_code == 200, awake.text
            await expect(heading).to_contain_text("online", timeout=20_000)
            await expect(heading).not_to_contain_text("hibernating")
