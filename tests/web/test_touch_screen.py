"""The robot's touch screen in a browser while its agent's screen server goes away and comes
back (an agent restart): it says so, raises no error, and reads the screen again."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from guidebot.bus import Bus, Endpoint
from guidebot.site.yamlio import load_site_file
from robot_agent.clock import Clock
from robot_agent.gui import OnboardScreen, ScreenServer

pytestmark = [pytest.mark.browser, pytest.mark.timeout(60)]

SITE = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"


def _screen(bus: Bus | None = None) -> OnboardScreen:
    """Robot R1's touch screen on the demo site, its link up."""
    return OnboardScreen(
        (bus or Bus()).endpoint("screen"),
        Clock(10.0),
        "R1",
        site=load_site_file(SITE),
        site_file=SITE,
        link_up=lambda: True,
    )


@contextlib.asynccontextmanager
async def touch_screen(open_page: Any) -> AsyncIterator[tuple[Any, Endpoint]]:
    """R1's touch screen in a 1024 x 600 browser page, and an endpoint that speaks to it as
    the robot's tasks do."""
    bus = Bus()
    onboard = _screen(bus)
    async with onboard:
        server = ScreenServer(onboard, port=0)
        await server.start()
        try:
            page = (await open_page(server.url, viewport=(1024, 600))).page
            yield page, bus.endpoint("task")
        finally:
            await open_page.close()
            await server.stop()


def assign_ground_tour(task: Endpoint) -> None:
    """The server gives R1 task t1, the English ground-floor tour (all of it the screen needs)."""
    task.publish(
        "task_assigned",
        {
            "task_id": "t1",
            "robot": "R1",
            "net": "give_tour",
            "params": {"tour": "ground", "lang": "en"},
        },
    )


async def test_the_touch_screen_rides_out_its_agent_restarting(open_page: Any) -> None:
    onboard = _screen()
    async with onboard:
        server = ScreenServer(onboard, port=0)
        await server.start()
        watch = await open_page(server.url, viewport=(1024, 600))
        watch.expect_error(r"ERR_CONNECTION_REFUSED")  # Chromium logs each refused request
        page = watch.page
        banner = page.locator("#connection")
        await expect(page.get_by_role("heading", name="Hello, I am R1")).to_be_visible()
        await expect(banner).to_be_hidden()
        await server.stop()
        await expect(banner).to_have_text("Connection lost: reconnecting…")
        # A tap meanwhile says the robot cannot be reached instead of failing silently.
        await page.get_by_role("button", name="Ground floor tour").click()
        await expect(page.get_by_role("status").last).to_contain_text("cannot be reached")
        again = ScreenServer(onboard, port=server.port)
        await again.start()
        try:
            await expect(banner).to_be_hidden(timeout=10_000)
            await expect(page.get_by_role("heading", name="Hello, I am R1")).to_be_visible()
        finally:
            await open_page.close()
            await again.stop()


async def test_the_touch_screen_says_when_its_agent_answers_with_an_error(open_page: Any) -> None:
    """An HTTP error from the agent is not a lost connection: the banner says the screen could
    not be read, the page asks again by itself, and the banner goes once the agent answers."""
    onboard = _screen()
    async with onboard:
        server = ScreenServer(onboard, port=0)
        await server.start()
        try:
            watch = await open_page(server.url, viewport=(1024, 600))
            watch.expect_error(r"status of 500")
            page = watch.page
            banner = page.locator("#connection")
            await expect(page.get_by_role("heading", name="Hello, I am R1")).to_be_visible()
            await page.route("**/api/screen*", lambda route: route.fulfill(status=500, body="{}"))
            await page.get_by_role("button", name="Español").click()
            await expect(banner).to_have_text("The robot's screen could not be read: trying again…")
            await expect(banner).to_have_attribute("data-status", "error")
            await page.unroute("**/api/screen*")
            await expect(banner).to_be_hidden(timeout=10_000)  # asked again, without a push
            await expect(page.locator("html")).to_have_attribute("lang", "es")
        finally:
            await open_page.close()
            await server.stop()


async def test_the_touch_screen_names_a_single_point_by_its_name_in_the_visitors_language(
    open_page: Any,
) -> None:
    """A go_to_poi's show_point carries only the point's id and text: the screen names it
    from the site in the task's language (with its picture), never by its id."""
    async with touch_screen(open_page) as (page, task):
        await expect(page.get_by_role("heading", name="Hello, I am R1")).to_be_visible()
        task.publish(
            "task_assigned",
            {
                "task_id": "t1",
                "robot": "R1",
                "net": "go_to_poi",
                "params": {"poi": "sword", "lang": "es"},
            },
        )
        task.publish("show_point", {"poi": "sword", "text": "Esta espada tiene tres mil años."})
        now = page.get_by_role("region", name="Ahora")
        name = "Espada de la Edad del Bronce"
        await expect(now.get_by_role("heading", level=3)).to_have_text(name)
        await expect(now.get_by_role("img", name=name)).to_be_visible()


async def test_on_the_way_to_the_first_stop_the_screen_says_which_tour_starts(
    open_page: Any,
) -> None:
    """Between the tour's assignment and its first stop the screen said "Guiding a tour" over
    "Touch a tour or a point to start." (seen on the busy demo): it now names the tour that
    is starting, in the tour's language, and offers no menu."""
    async with touch_screen(open_page) as (page, task):
        now = page.get_by_role("region", name="Now")
        await expect(now).to_contain_text("Touch a tour or a point to start.")
        assign_ground_tour(task)
        await expect(now).to_contain_text(
            "Ground floor tour is starting: come with me to the first stop."
        )
        await expect(now).not_to_contain_text("Touch a tour")
        await expect(page.get_by_role("region", name="Tours")).to_have_count(0)


async def test_on_the_way_to_the_next_stop_the_last_one_is_not_called_now(
    open_page: Any, web: SimpleNamespace
) -> None:
    """Walking to stop 2, the screen kept stop 1 under "Now" beside "Going to the next stop…"
    (seen on the busy demo): the stop the group just left is "Just seen" until the next one."""
    async with touch_screen(open_page) as (page, task):
        assign_ground_tour(task)
        point = {"index": 1, "total": 5, "name": "Welcome hall"}
        task.publish("show_point", {"poi": "welcome", "point": point, "text": "Welcome."})
        now = page.get_by_role("region", name="Now")
        await expect(now).to_contain_text("Stop 1 of 5: Welcome hall")
        task.publish("navigate_to", {"node": "ga1"})
        just_seen = page.get_by_role("region", name="Just seen")
        await expect(just_seen).to_contain_text("Stop 1 of 5: Welcome hall")
        await expect(page.get_by_role("status")).to_contain_text("Going to the next stop")
        task.publish("goal_reached", {"node": "ga1"})
        await expect(now).to_contain_text("Stop 1 of 5: Welcome hall")
        await web.axe_check(page)


async def test_during_a_tour_the_language_buttons_say_the_screen_follows_the_tour(
    open_page: Any, web: SimpleNamespace
) -> None:
    """A tap on "Español" during an English tour did nothing at all (the screen goes back to
    the tour's language at once; seen on the busy demo): during a task the buttons are off and
    say why; after it, a tap changes the language again."""
    async with touch_screen(open_page) as (page, task):
        languages = page.get_by_role("group", name="Language")
        await expect(languages.get_by_role("button", name="Español")).to_be_enabled()
        assign_ground_tour(task)
        await expect(page.get_by_role("region", name="Now")).to_contain_text("is starting")
        spanish = languages.get_by_role("button", name="Español")
        await expect(spanish).to_be_disabled()
        await expect(page.locator("#lang-help")).to_have_text(
            "During a visit the screen speaks its visitor's language."
        )
        await expect(spanish).to_have_attribute("aria-describedby", "lang-help")
        await web.axe_check(page)
        task.publish("task_ended", {"task_id": "t1", "robot": "R1", "state": "done"})
        await expect(page.get_by_role("region", name="Tours")).to_be_visible()
        await spanish.click()
        await expect(page.get_by_role("heading", name="Hola, soy R1")).to_be_visible()


async def test_the_continue_question_is_accessible_while_it_is_open(
    open_page: Any, web: SimpleNamespace
) -> None:
    """The "continue?" dialog under axe. In a tour (tests/web/test_visitor.py) it stays open 5 s
    of wall time, which axe outlasted on a loaded machine; here it is asked for 600 robot
    seconds, more than the test's time-out, so it is open for the whole check."""
    async with touch_screen(open_page) as (page, task):
        assign_ground_tour(task)
        point = {"index": 1, "total": 5, "name": "Welcome hall"}
        task.publish("show_point", {"poi": "welcome", "point": point, "text": "Welcome."})
        task.publish("ask_continue", {"question": "Shall we continue the tour?", "timeout_s": 600})
        question = page.get_by_role("alertdialog", name="Shall we continue the tour?")
        await expect(question).to_be_visible()
        await expect(question.get_by_role("timer")).to_contain_text("s left to answer")
        await expect(question.get_by_role("button", name="No, thanks")).to_be_visible()
        await web.axe_check(page)
        await expect(question).to_be_visible()  # still open: axe saw the dialog
