"""Tours for every visitor (issue 41), in a real browser against a real server and simulated
robots: the touch screen captions what the robot says, in time and in the tour's language; a
screen reader hears every change of a request on the phone (Chromium's accessibility tree).
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from tests.web.test_visitor import KIOSK, LONG, PHONE, request_from
from tests.web.test_visitor import visitor_fleet as visitor_fleet  # the fixture

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

CAPTION_LATE_S = 0.5
"""A caption shows at most this long after its speech started (issue 41)."""


async def live_region_of(page: Any, text: str) -> str | None:
    """The aria-live value ("polite", "assertive") of the live region holding ``text`` in
    Chromium's accessibility tree (what a screen reader is told), None when no live region
    holds it."""
    cdp = await page.context.new_cdp_session(page)
    try:
        nodes = (await cdp.send("Accessibility.getFullAXTree"))["nodes"]
    finally:
        await cdp.detach()
    by_id = {n["nodeId"]: n for n in nodes}
    for node in nodes:
        if text not in str((node.get("name") or {}).get("value", "")):
            continue
        at: dict[str, Any] | None = node
        while at is not None:
            live = {p["name"]: p["value"].get("value") for p in at.get("properties", [])}
            if live.get("live") in ("polite", "assertive"):
                return str(live["live"])
            at = by_id.get(at.get("parentId", ""))
    return None


async def test_the_touch_screen_captions_each_utterance_within_half_a_second_in_its_language(
    visitor_fleet: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with visitor_fleet(time_scale=10.0) as vf:
        panel = (await open_page(vf.panel_url(extra="&kiosk=1"), viewport=KIOSK)).page
        screen = (await open_page(vf.screen_url(), viewport=(1024, 600))).page
        await panel.get_by_role("button", name="Español").click()
        await request_from(panel, "Lo imprescindible", "Hacer esta visita")
        caption = screen.locator(".captions .caption")
        await expect(caption).to_contain_text("mosaicos", timeout=LONG)
        assert await caption.get_attribute("lang") == "es"
        await web.axe_check(screen)
        await web.screenshot(screen, "touch-screen-captions")
        shown = await screen.evaluate("window.captionsShown")
        started = {round(m.timestamp * 1000): m.payload for m in vf.speech}
        assert any("mosaicos" in c["text"] for c in shown)
        for c in shown:
            said = started[round(c["started_at"] * 1000)]  # each caption is an utterance's
            assert c["text"] == said["text"] and said["lang"] == "es"
            late = c["shown_at"] / 1000 - c["started_at"]
            assert late <= CAPTION_LATE_S, f"caption {late:.3f} s after its speech: {c['text']}"


async def test_a_screen_reader_hears_each_change_of_a_request_on_the_phone(
    visitor_fleet: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with visitor_fleet() as vf:
        page = (await open_page(vf.panel_url(), viewport=PHONE)).page
        await expect(page.get_by_role("status").first).to_contain_text("A robot is free now")
        # A staff tour keeps the robot busy: the visitor waits in line first.
        async with vf.fleet.http() as staff:
            r = await staff.post(
                "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "sword"}}
            )
            assert r.status_code == 201, r.text
        await expect(page.get_by_role("status").first).to_contain_text(
            "Every robot is busy", timeout=LONG
        )
        await request_from(page, "Highlights")
        announcer = page.locator("#announcer")
        await expect(announcer).to_contain_text("You are number 1 in line.")
        await web.axe_check(page)
        for said in (
            "You are number 1 in line.",
            "Robot R1 is coming for you.",
            "Stop 1 of 3",
            "Stop 2 of 3",
            "Stop 3 of 3",
            "The tour has ended.",
        ):
            await expect(announcer).to_contain_text(said, timeout=LONG)
            assert await announced_live(page), said
        # The visible lines are not a second live region: a screen reader hears each once.
        assert await live_region_of(page, "The tour has ended.") == "polite"
        assert await page.locator(".request-state[aria-live], .request-state[role]").count() == 0


async def announced_live(page: Any) -> bool:
    """Whether the announcer's current words sit in a live region of the accessibility tree
    (read again when the state moved on between the two reads)."""
    for _ in range(5):
        words = (await page.locator("#announcer").text_content() or "").strip()
        if words and await live_region_of(page, words) == "polite":
            return True
    return False
