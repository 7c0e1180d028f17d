"""Publishing from the RoboGraph editor (/nets/, docs/nets.md "Publish") in a real browser
against a real server and a real robot agent: explain_point's words edited and published while
a tour runs; the running tour keeps its words, the next tour speaks the new ones; the history
shows who published what, compares it with the shipped file and restores it."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from guidebot.messages import Message
from guidebot.testing import wait_until

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]

NEW_WORDS = '{"text": "New words: ${text}", "lang": "${lang}"}'


def two_point_tour(data: dict[str, Any]) -> None:
    data["tours"] += [{"id": "short", "name": "Short tour", "points": ["welcome", "mosaics"]}]


async def open_explain_point(page: Any, token: str) -> None:
    """Sign in to the editor and open the library's explain_point."""
    await page.get_by_label("Staff token").fill(token)
    await page.get_by_label("Staff token").press("Enter")
    await page.get_by_label("Library net").select_option("explain_point")
    await page.get_by_role("button", name="Open", exact=True).click()
    await expect(page.get_by_role("heading", name="Versions of explain_point")).to_be_visible()


async def write_new_words(page: Any) -> Any:
    """Give synthesize_text the payload NEW_WORDS, as a person does (the edit lands on Tab);
    returns the payload's field."""
    await (
        page.locator("#lists")
        .get_by_role("button", name="synthesize text (synthesize_text)")
        .click()
    )
    payload = page.get_by_label("Payload (JSON, ${parameter} allowed)")
    await payload.fill(NEW_WORDS)
    await payload.press("Tab")
    return payload


async def test_edit_explain_point_publish_and_the_next_tour_speaks_the_new_words(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1, time_scale=4, edit=two_point_tour) as fleet:
        robot = fleet.agents["R1"]
        # The robot has no touch screen here: the visitor answers "continue?" when the test
        # says so, and the tour waits there (for patience_s, 30 s robot time).
        spoken: list[Message] = []
        asked: list[Message] = []
        visitor = robot.bus.endpoint("test-visitor")
        visitor.subscribe("speech_started", spoken.append, tap=True)
        visitor.subscribe("ask_continue", asked.append, tap=True)
        ended: list[Message] = []
        visitor.subscribe("task_ended", ended.append, tap=True)
        watch = await open_page(f"{fleet.server.url}/nets/")
        page = watch.page
        await open_explain_point(page, fleet.server.admin_token)
        await write_new_words(page)
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        await page.get_by_label("What changed").fill("A warmer welcome")

        # A tour starts on the shipped words and waits at its first "continue?".
        async with fleet.http() as http:
            reply = await http.post(
                "/api/tasks", json={"kind": "tour", "params": {"tour": "short"}, "robot": "R1"}
            )
            assert reply.status_code == 201, reply.text
            first_tour = reply.json()["id"]
        await wait_until(lambda: bool(asked), timeout=60)
        assert [m.payload["text"] for m in spoken] == [spoken[0].payload["text"]]
        assert not spoken[0].payload["text"].startswith("New words")

        await page.get_by_role("button", name="Publish explain_point to the fleet").click()
        await expect(page.locator("#notices")).to_contain_text("explain_point version 1 published")
        await wait_until(lambda: robot.net_follower.version == 1)
        versions = page.get_by_role("list", name="Versions of explain_point")
        await expect(versions).to_contain_text("Version 1 live")
        await expect(versions).to_contain_text("A warmer welcome")
        await web.axe_check(page)
        await web.screenshot(page, "nets-publish")

        # The tour running goes on with the words it started with.
        visitor.publish("continue_answer", {"answer": "yes"})
        await wait_until(lambda: any(m.payload["task_id"] == first_tour for m in ended), timeout=60)
        assert len(spoken) == 2
        assert not spoken[1].payload["text"].startswith("New words"), spoken[1].payload

        # The next tour speaks the new ones.
        async with fleet.http() as http:
            reply = await http.post(
                "/api/tasks", json={"kind": "tour", "params": {"tour": "short"}, "robot": "R1"}
            )
            assert reply.status_code == 201, reply.text
        await wait_until(lambda: len(spoken) == 3, timeout=60)
        assert spoken[2].payload["text"] == f"New words: {spoken[0].payload['text']}"

        # The history compares with the shipped file and restores it.
        await page.get_by_role("button", name="Compare with live: version 0 (shipped)").click()
        await expect(page.locator("#diff")).to_contain_text("~ place synthesize_text: action.body")
        await page.get_by_role("button", name="Restore version 0 (shipped)").click()
        await expect(page.locator("#notices")).to_contain_text(
            "explain_point version 0 restored as version 2"
        )
        await expect(versions).to_contain_text("Version 2 live")
        await wait_until(lambda: robot.net_follower.version == 2)
        await expect(page.locator("#lists")).to_contain_text("synthesize_text")
        await web.axe_check(page)


async def test_a_publish_that_went_through_says_so_when_the_lists_cannot_be_read_after(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The publish is one call; reading the library and the robots again after it is another.
    When that read failed, the page said "Not published: …" of a net the fleet runs now."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(f"{fleet.server.url}/nets/")
        watch.expect_error(r"status of 503")
        page = watch.page
        await open_explain_point(page, fleet.server.admin_token)
        await write_new_words(page)
        await expect(page.locator("#problem-count")).to_have_text("No problems")

        async def unavailable(route: Any) -> None:
            await route.fulfill(status=503, json={"detail": "restarting"})

        await page.route("**/api/nets", unavailable)  # the library's list, read after publishing
        await page.get_by_role("button", name="Publish explain_point to the fleet").click()
        notices = page.locator("#notices")
        await expect(notices).to_contain_text("explain_point version 1 published")
        await expect(notices).not_to_contain_text("Not published")
        await web.axe_check(page)
        async with fleet.http() as http:
            versions = (await http.get("/api/net-editor/versions/explain_point")).json()
        assert versions["live"] == 1, versions


async def test_opening_another_net_asks_before_dropping_changes_not_published(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """Edits live only in the tab until published: opening another net dropped them without a
    word, and nothing said they were not published. The bar says so, opening another net asks
    first, and once published nothing is asked."""
    async with fleet_factory(robots=0) as fleet:
        page = (await open_page(f"{fleet.server.url}/nets/")).page
        await open_explain_point(page, fleet.server.admin_token)
        unpublished = page.locator("#unpublished")
        await expect(unpublished).to_have_count(0)
        payload = await write_new_words(page)
        await expect(unpublished).to_have_text("Changes not published")
        await web.axe_check(page)
        await page.get_by_label("Library net").select_option("give_tour")
        await page.get_by_role("button", name="Open", exact=True).click()
        ask = page.get_by_role("dialog", name="Drop your changes to explain_point?")
        await expect(ask).to_be_visible()
        await web.axe_check(page)
        await ask.get_by_role("button", name="Keep editing explain_point").click()
        await expect(ask).to_have_count(0)
        await expect(page.get_by_role("heading", name="Versions of explain_point")).to_be_visible()
        await expect(payload).to_have_value(NEW_WORDS)
        await page.get_by_role("button", name="Publish explain_point to the fleet").click()
        await expect(page.locator("#notices")).to_contain_text("explain_point version 1 published")
        await expect(unpublished).to_have_count(0)
        await page.get_by_label("Library net").select_option("give_tour")
        await page.get_by_role("button", name="Open", exact=True).click()
        await expect(page.locator("#notices")).to_contain_text("Net give_tour opened")
        await expect(page.get_by_role("dialog")).to_have_count(0)
