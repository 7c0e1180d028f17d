"""Handover as the visitor sees it (issue 36), in a real browser against a real server, the
building simulator and two simulated robots with their touch screens: the visitor's robot is
taken out of service in the middle of the tour; the panel says which robot continues from which
stop and when it will be there, the new robot's touch screen says so too, and the tour ends."""

from __future__ import annotations

import contextlib
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from guidebot.site.schema import Site
from robot_agent.testing import light_robot

pytestmark = [pytest.mark.browser, pytest.mark.timeout(150)]

PANEL = "panel-handover-token"
PHONE = (360, 740)
LONG = 60_000


async def test_the_panel_and_the_new_robots_screen_say_who_continues_from_which_stop(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Site
) -> None:
    async with fleet_factory(robots=0) as fleet, contextlib.AsyncExitStack() as stack:
        fleet.server.app.state.tokens.add(PANEL, "panel-handover", "panel")
        agents = {}
        for robot in demo_site.robots[:2]:
            agent = light_robot(
                fleet.server.url,
                robot.name,
                robot.token,
                site=fleet.site_file,
                start_node=robot.start_node,
                time_scale=40.0,
            )
            await stack.enter_async_context(agent)
            agents[robot.name] = agent
        stack.push_async_callback(open_page.close)
        page = (await open_page(f"{fleet.server.url}/visitor/#token={PANEL}", viewport=PHONE)).page
        await expect(page.get_by_role("status").first).to_contain_text(
            "A robot is free now", timeout=LONG
        )
        card = page.get_by_role("article", name="Highlights")
        await card.get_by_role("button", name="Take this tour").click()
        state = page.locator(".request-state")
        await expect(state).to_contain_text("Stop 2 of 3", timeout=LONG)
        manager = fleet.server.app.state.task_manager
        [task] = [t for t in manager.tasks.values() if not t.internal]
        first = task.robot
        other = next(n for n in agents if n != first)
        stop = manager.estimator.progress_view(task)["index"]
        async with fleet.http() as staff:
            r = await staff.post(f"/api/robots/{first}/service", json={"out_of_service": True})
            assert r.status_code == 200, r.text
        await expect(state).to_contain_text(
            f"{other} continues your tour from stop {stop}", timeout=LONG
        )
        await web.axe_check(page)
        screen = (await open_page(agents[other].screen_server.url, viewport=(1024, 600))).page
        await expect(
            screen.get_by_role("status").filter(has_text="continues your tour")
        ).to_contain_text(f"{other} continues your tour from stop {stop}", timeout=LONG)
        await expect(state).to_contain_text("The tour has ended", timeout=LONG)
        assert task.handover is not None and task.handover["arrived_after_s"] is not None
