"""The next booked public tours on the visitor panel and a robot's touch screen, in a real
browser against a real server and a simulated robot: "Spanish tour at 14:00, meet at the
Welcome hall" in the visitor's language, updated live when staff book another
(docs/visitor.md, docs/server.md "Bookings")."""

from __future__ import annotations

import datetime as dt
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

PANEL = "panel-next-tours-token"


def midday_zone() -> tuple[str, dt.datetime]:
    """A fixed-offset zone where it is now between 10:00 and 13:00 (so "in an hour" and "in
    two hours" are still today), and the local time now there."""
    now = dt.datetime.now(dt.UTC)
    offset = 11 - now.hour
    offset = offset + 24 if offset < -12 else offset - 24 if offset > 14 else offset
    zone = f"Etc/GMT{-offset:+d}"  # the Etc names count west positive
    return zone, now + dt.timedelta(hours=offset)


async def test_the_panel_and_the_touch_screen_show_the_next_booked_tours(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    zone, local = midday_zone()
    first = (local + dt.timedelta(hours=1)).strftime("%Y-%m-%dT%H:%M")
    second = (local + dt.timedelta(hours=2)).strftime("%Y-%m-%dT%H:%M")
    async with fleet_factory(robots=1, screens=True, timezone=zone) as fleet:
        fleet.server.app.state.tokens.add(PANEL, "panel-next", "panel")
        async with fleet.http(web.operator_token) as staff:
            made = await staff.post(
                "/api/bookings",
                json={
                    "tour": "highlights",
                    "start": first,
                    "lang": "es",
                    "group_size": 25,
                    "meeting_point": "welcome",
                },
            )
            assert made.status_code == 201, made.text
            private = {"tour": "ground", "start": first, "lang": "de", "group_size": 9}
            made = await staff.post("/api/bookings", json={**private, "public": False})
            assert made.status_code == 201, made.text

        visitor = await open_page(f"{fleet.server.url}/visitor/#token={PANEL}")
        panel = visitor.page
        booked = panel.get_by_role("region", name="Booked tours today")
        await expect(booked.get_by_role("listitem")).to_have_text(
            [f"Highlights: Spanish tour at {first[11:]}, meet at the Welcome hall"]
        )
        await web.axe_check(panel)
        await web.screenshot(panel, "visitor-next-tours")
        await panel.get_by_role("button", name="Español").click()
        booked = panel.get_by_role("region", name="Visitas reservadas hoy")
        await expect(booked.get_by_role("listitem")).to_have_text(
            [
                f"Lo imprescindible: Visita en español a las {first[11:]}, "
                "punto de encuentro: Vestíbulo"
            ]
        )

        agent = fleet.agents["R1"]
        assert agent.screen_server is not None
        screen = (await open_page(agent.screen_server.url, viewport=(1024, 600))).page
        on_screen = screen.get_by_role("region", name="Booked tours today")
        await expect(on_screen.get_by_role("listitem")).to_have_count(1)

        # Staff book another: both pages show it without a reload.
        async with fleet.http(web.operator_token) as staff:
            made = await staff.post(
                "/api/bookings",
                json={"tour": "upstairs", "start": second, "lang": "de", "group_size": 4},
            )
            assert made.status_code == 201, made.text
        await expect(booked.get_by_role("listitem")).to_have_count(2)
        await expect(booked.get_by_role("listitem").nth(1)).to_contain_text(
            f"Visita en alemán a las {second[11:]}"
        )
        await expect(on_screen.get_by_role("listitem").nth(1)).to_have_text(
            f"First floor tour: German tour at {second[11:]}, meet at the Tapestries"
        )
        await web.axe_check(screen)
