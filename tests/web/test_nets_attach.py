"""The RoboGraph editor attached to a running robot (docs/nets.md, "Attach") in a real browser,
against a real server and robot agent: the live marking of its idle net, a breakpoint that
pauses it before a transition, step and resume, the breakpoint cleared when the page goes,
and kill."""

from __future__ import annotations

import re
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from guidebot.testing import wait_until

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]


def feed_knows_idle_net(fleet: Any) -> bool:
    """The server has heard of R1's idle net: the robot starts it before its link is up, and
    petri_net_event goes up only while the link is, so the server learns of it at its first
    firing (noticed, docs/nets.md)."""
    running = fleet.server.app.state.console.running_nets("R1")
    return any(n["net"] == "waiting" for n in running)


def held(robot: Any) -> list[dict[str, Any]]:
    """The robot's instances a debugger holds (breakpoints set or paused)."""
    return [i for i in robot.dispatch.running() if i.get("breakpoints")]


async def test_attach_to_a_robot_break_step_resume_and_the_page_going_clears_it(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1, time_scale=4) as fleet:
        robot = fleet.agents["R1"]
        await wait_until(lambda: feed_knows_idle_net(fleet), timeout=30)
        watch = await open_page(f"{fleet.server.url}/nets/")
        page = watch.page
        await page.get_by_label("Staff token").fill(fleet.server.admin_token)
        await page.get_by_label("Staff token").press("Enter")
        await page.get_by_label("Robot").select_option("R1")
        await page.get_by_role("button", name="Show running nets").click()
        attach = page.get_by_role("button", name=re.compile(r"^Attach to waiting#"))
        await attach.click()
        status = page.locator("#attach-status")
        await expect(status).to_contain_text(re.compile(r"waiting#\d+ is running"))
        # The live marking: the idle place holds its token while its timer runs.
        idle = page.locator('#canvas g[data-id="idle"]')
        await expect(idle).to_have_attribute("aria-label", re.compile(r"1 token\(s\)"))

        await page.get_by_role("checkbox", name="bored").check()
        await expect(status).to_contain_text("is paused before bored", timeout=30_000)
        instance = held(robot)[0]
        assert instance["paused_at"] == "bored" and instance["breakpoints"] == ["bored"]
        await expect(page.locator('#canvas g[data-id="bored"]')).to_have_class(
            re.compile(r"\bfired\b")
        )
        await web.axe_check(page)
        await web.screenshot(page, "nets-attach")
        # Step: bored fires, and the instance holds before its next firing.
        await page.get_by_role("button", name="Step", exact=True).click()
        await expect(status).to_contain_text(
            re.compile(r"is paused before (do_blink|do_wink|nothing)")
        )
        await expect(idle).not_to_have_attribute("aria-label", re.compile("token"))
        # Resume: to the breakpoint again, a pause_s later.
        await page.get_by_role("button", name="Resume").click()
        await expect(status).to_contain_text("is paused before bored", timeout=30_000)

        # The page goes: its breakpoints go, and the net runs on.
        await page.goto("about:blank")
        await wait_until(lambda: held(robot) == [], timeout=20)

        # Back, attached again: kill (admin).
        await page.goto(f"{fleet.server.url}/nets/")
        await page.get_by_label("Robot").select_option("R1")
        await page.get_by_role("button", name="Show running nets").click()
        await page.get_by_role("button", name=re.compile(r"^Attach to waiting#")).click()
        await expect(status).to_contain_text("is running")
        await page.get_by_role("button", name=re.compile(r"^Kill waiting#")).click()
        await expect(status).to_contain_text(re.compile(r"waiting#\d+ ended"))
