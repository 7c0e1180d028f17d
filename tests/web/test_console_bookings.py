"""Bookings in the console, in a real browser against a real server: book a recurring Spanish
tour, move it, read its history, cancel one date and then the booking; a fourth booking at once
for three robots is refused with the reason (docs/console.md, "Bookings")."""

from __future__ import annotations

import datetime as dt
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


def day(offset: int) -> str:
    return (dt.datetime.now(dt.UTC).date() + dt.timedelta(days=offset)).isoformat()


async def test_staff_book_move_and_cancel_a_tour_in_the_console(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        console = await open_page(fleet.admin_url)
        page = console.page
        await web.sign_in(console, web.operator_token)
        await web.open_view(page, "Bookings")
        form = page.locator("form.book-form")
        await form.get_by_label("Tour or visit").select_option(label="Highlights")
        await form.get_by_label("Date and time").fill(f"{day(1)}T14:00")
        await form.get_by_label("Language").select_option("es")
        await form.get_by_label("Group size").fill("25")
        await form.get_by_label("Note").fill("School group")
        await form.get_by_label("Repeats").select_option("daily")
        await form.get_by_label("Except (closed days)").fill(day(3))
        await form.get_by_role("button", name="Book it").click()
        table = page.get_by_role("table", name=f"Bookings on {day(1)}")
        row = table.get_by_role("row").filter(has_text="Highlights")
        await expect(row).to_contain_text("14:00")
        await expect(row).to_contain_text("School group")
        await expect(row).to_contain_text("every day")
        await expect(row).to_contain_text("Roman mosaics")  # the first stop, by default
        await web.axe_check(page)
        await web.screenshot(page, "console-bookings")

        await row.get_by_role("button", name="Move Highlights at 14:00").click()
        move = page.locator("form.move-form")
        await move.get_by_label("New date and time").fill(f"{day(1)}T15:30")
        await move.get_by_label("Group size").fill("30")
        await move.get_by_role("button", name="Move it").click()
        await expect(row).to_contain_text("15:30")
        await expect(row).to_contain_text("30")
        await row.get_by_role("button", name="History of Highlights at 15:30").click()
        history = page.get_by_role("table", name="Booking history")
        await expect(history.get_by_role("row")).to_have_count(3)  # header, created, moved
        await expect(history).to_contain_text("14:00 → " + f"{day(1)}T15:30")
        await expect(history).to_contain_text("desk")

        # The third day is a closed day: nothing then. Cancel only the next day's.
        await page.get_by_role("button", name="Next day").click()
        await page.get_by_role("button", name="Next day").click()
        await expect(page.get_by_role("cell", name=f"Nothing booked on {day(3)}.")).to_be_visible()
        await page.get_by_role("button", name="Previous day").click()
        row = page.get_by_role("table", name=f"Bookings on {day(2)}").get_by_role("row")
        await (
            row.filter(has_text="Highlights")
            .get_by_role("button", name=f"Cancel Highlights on {day(2)} only")
            .click()
        )
        await expect(page.get_by_role("cell", name=f"Nothing booked on {day(2)}.")).to_be_visible()

        # Three robots: a fourth tour at once is refused, and the page says why.
        async with fleet.http(web.operator_token) as staff:
            for _ in range(2):
                answer = await staff.post(
                    "/api/bookings",
                    json={
                        "tour": "ground",
                        "start": f"{day(1)}T15:30",
                        "lang": "en",
                        "group_size": 4,
                    },
                )
                assert answer.status_code == 201, answer.text
        await page.get_by_role("button", name="Previous day").click()
        form = page.locator("form.book-form")
        await form.get_by_label("Date and time").fill(f"{day(1)}T15:30")
        console.expect_error(r"status of 422")
        await form.get_by_role("button", name="Book it").click()
        await expect(page.get_by_role("alert")).to_contain_text(
            f"4 bookings at once at {day(1)}T15:30 but 3 robot(s) in service"
        )
        row = page.get_by_role("table", name=f"Bookings on {day(1)}").get_by_role("row")
        await (
            row.filter(has_text="Highlights")
            .get_by_role("button", name="Cancel Highlights at 15:30")
            .click()
        )
        await expect(row.filter(has_text="Highlights")).to_have_count(0)


async def test_the_bookings_view_follows_bookings_made_elsewhere(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """A booking made on another screen (or a robot reserved, a tour started) comes with no
    message of its own: the view read the day once and kept saying so. It reads the day again
    while it is shown."""
    async with fleet_factory(robots=0) as fleet:
        console = await open_page(fleet.admin_url)
        page = console.page
        await web.sign_in(console, web.operator_token)
        await web.open_view(page, "Bookings")
        await page.get_by_role("button", name="Next day").click()
        table = page.get_by_role("table", name=f"Bookings on {day(1)}")
        await expect(table).to_contain_text("Nothing booked")
        async with fleet.http(web.operator_token) as http:
            reply = await http.post(
                "/api/bookings",
                json={
                    "tour": "highlights",
                    "start": f"{day(1)}T14:00",
                    "lang": "en",
                    "group_size": 8,
                },
            )
            assert reply.status_code == 201, reply.text
        row = table.get_by_role("row").filter(has_text="Highlights")
        await expect(row).to_contain_text("14:00", timeout=20_000)
        await expect(row.get_by_role("button", name="Move Highlights at 14:00")).to_be_visible()

        # Its tour starts (the scheduler's record of it, as at its time): the row said so and
        # still offered Move and Cancel, which the server now refuses. It offers neither.
        booking = reply.json()
        bookings = fleet.server.app.state.bookings
        at = bookings.between(0, 2**40)[0][0]
        bookings.outcomes[(booking["id"], at)] = {"task_id": "t-42", "outcome": "started"}
        await page.get_by_role("button", name="Refresh").click()
        await expect(row).to_contain_text("started (task t-42)")
        await expect(row.get_by_role("button")).to_have_text(["History of Highlights at 14:00"])
        async with fleet.http(web.operator_token) as http:
            refused = await http.post(f"/api/bookings/{booking['id']}/cancel", json={})
        assert refused.status_code == 422, refused.text
        assert "has started (task t-42)" in refused.json()["detail"]
