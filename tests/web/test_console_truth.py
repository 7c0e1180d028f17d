"""The staff console says what the server says (issue 33, "The staff console"): the tasks view
equals GET /api/tasks after live updates, the event log holds the history from before sign-in
and reports its failures, irreversible actions ask first."""

from __future__ import annotations

import asyncio
import re
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

QUEUE_ROWS = """() => [...document.querySelectorAll('table[aria-label="Queued tasks"] tbody tr')]
    .map(tr => [tr.dataset.task, tr.cells[0].textContent.trim(), tr.cells[2].textContent.trim(),
                tr.cells[3].textContent.trim(), tr.querySelector('input[type=number]').value])"""


async def api_queue(http: httpx.AsyncClient) -> list[list[str]]:
    """The queue as GET /api/tasks lists it, in the shape QUEUE_ROWS reads the page."""
    tasks = (await http.get("/api/tasks", params={"limit": 300})).json()["tasks"]
    return [
        [
            t["id"],
            str(t["queue_position"]),
            str(t["priority"]),
            t["pinned_robot"] or "any",
            str(t["priority"]),
        ]
        for t in tasks
        if t["state"] == "queued"
    ]


async def wait_queue_equals(page: Any, expected: list[list[str]]) -> None:
    await page.wait_for_function(
        f"expected => JSON.stringify(({QUEUE_ROWS})()) === JSON.stringify(expected)",
        arg=expected,
        timeout=20_000,
    )


EVENT_PAGE = 1000
"""Rows of the event log the console loads at once (web/admin/store.js)."""
EVENTS = re.compile(r"/api/events\?")
A_PAGE_LOADED = re.compile(r"^1\d{3} events loaded")
"""The event count once the console loaded a page: 1000, or a few more logged live since."""


async def logged(http: httpx.AsyncClient) -> int:
    """How many rows the event log holds (GET /api/events, a page at a time)."""
    count, after = 0, 0
    while True:
        page = (await http.get("/api/events", params={"after_id": after, "limit": 1000})).json()
        count += len(page["events"])
        if not page["events"]:
            return count
        after = page["next_after_id"]


class LiveConnection:
    """The page's live connection (the hub's WebSocket), passed through Playwright so that a
    test can drop it as a network would: the page reconnects and reloads its snapshot."""

    def __init__(self) -> None:
        self.page: Any = None
        self.sockets: list[Any] = []
        self.opened = asyncio.Event()

    @classmethod
    async def route(cls, page: Any) -> LiveConnection:
        """Route the page's /ws (before it opens it)."""
        live = cls()

        def through(ws: Any) -> None:
            ws.connect_to_server()
            live.sockets.append(ws)
            live.opened.set()

        await page.route_web_socket(re.compile(r"/ws(\?|$)"), through)
        live.page = page
        return live

    async def drop(self) -> None:
        """Close the connection as a restarting server would; return once the page is
        connected again (its banner says so), so its reload has begun."""
        self.opened.clear()
        await self.sockets[-1].close(code=1012, reason="server restarting")
        await self.opened.wait()
        await expect(self.page.locator("#connection")).to_have_text("Connected")


async def request_tours(http: httpx.AsyncClient, tours: list[str]) -> list[str]:
    ids = []
    for tour in tours:
        reply = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": tour}})
        assert reply.status_code == 201, reply.text
        ids.append(reply.json()["id"])
    return ids


async def test_set_priority_moves_the_task_and_every_position_as_the_server_does(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        async with fleet.http() as http:
            ids = await request_tours(http, ["ground", "upstairs", "highlights"])
            watch = await open_page(fleet.admin_url)
            page = watch.page
            await web.sign_in(watch, web.operator_token)
            await web.open_view(page, "Tasks")
            await wait_queue_equals(page, await api_queue(http))
            last = page.locator(f'tr[data-task="{ids[2]}"]')
            await last.get_by_role("spinbutton").fill("90")
            await last.get_by_role("button", name="Set priority").click()
            await expect(
                page.get_by_role("status").filter(has_text="Priority of Tour: ")
            ).to_contain_text("done")
            expected = await api_queue(http)
            assert [row[0] for row in expected] == [ids[2], ids[0], ids[1]]
            assert expected[0][2] == "90"
            await wait_queue_equals(page, expected)
            # The names of the site, not its ids.
            await expect(last).to_contain_text("Tour: ")
            await web.axe_check(page)


async def test_event_log_has_the_history_and_concurrent_reloads_agree(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        async with fleet.http() as http:
            # A busy day: more rows than the console loads at once.
            store = fleet.server.app.state.store
            for i in range(EVENT_PAGE):
                store.record_event("test_note", "test", {"n": i})
            await store.flush()
            await request_tours(http, ["ground", "upstairs"])
            before = await http.get("/api/events", params={"latest": "true", "limit": 1000})
            assert len(before.json()["events"]) == EVENT_PAGE
            assert EVENT_PAGE + 3 <= await logged(http) <= 2 * EVENT_PAGE
            watch = await open_page("")
            page = watch.page
            hub = await LiveConnection.route(page)
            await page.goto(fleet.admin_url)
            await web.sign_in(watch, web.operator_token)
            await web.open_view(page, "Event log")
            count = page.locator("#event-count")
            # A page of the log (and what was logged live since: the building's alerts...).
            await expect(count).to_contain_text(A_PAGE_LOADED, timeout=20_000)
            older = page.get_by_role("button", name="Load older events")
            await expect(older).to_be_visible()
            # Ids are named: the task's tour.
            await expect(page.get_by_role("table", name="Events")).to_contain_text(
                "task=Tour: First floor tour ("
            )
            # Two reloads at once: the live connection drops twice while the first reload's
            # snapshot is still on its way; both complete and the page agrees with the server.
            held, release = asyncio.Event(), asyncio.Event()

            async def slow_events(route: Any) -> None:
                held.set()
                await release.wait()
                await route.continue_()

            await page.route(EVENTS, slow_events)
            await hub.drop()
            await held.wait()
            await hub.drop()
            release.set()
            await expect(page.locator("#connection")).to_have_text("Connected")
            await expect(count).to_contain_text(A_PAGE_LOADED)
            await expect(older).to_be_visible()
            await expect(page.locator("#page-error")).to_have_text("")
            await page.unroute(EVENTS)
            # Paged back from the REST log, a page at a time: then the page holds all of it.
            await older.click()
            # A thousand rows more to fetch and draw: as long as the first page may take.
            await expect(page.get_by_text("That is the whole event log.")).to_be_visible(
                timeout=20_000
            )
            await expect(count).to_contain_text(f"{await logged(http)} events loaded")
            # A refresh that fails says so on the page.
            watch.expect_error(r"status of 500")
            await page.route("**/api/locks", lambda route: route.fulfill(status=500, body="{}"))
            await hub.drop()
            await expect(page.locator("#page-error")).to_contain_text("could not refresh")
            await page.unroute("**/api/locks")
            await hub.drop()
            await expect(page.locator("#page-error")).to_have_text("")
            # The REST log pages back from the oldest row shown.
            ids = [e["id"] for e in before.json()["events"]]
            older = await http.get(
                "/api/events", params={"latest": "true", "before_id": ids[-1], "limit": 2}
            )
            assert [e["id"] for e in older.json()["events"]] == ids[-3:-1]


async def test_cancelling_a_task_asks_first_and_tells_the_requester(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        async with fleet.http() as http:
            [task] = await request_tours(http, ["ground"])
            watch = await open_page(fleet.admin_url)
            page = watch.page
            await web.sign_in(watch, web.operator_token)
            await web.open_view(page, "Tasks")
            row = page.locator(f'tr[data-task="{task}"]')
            await row.get_by_role("button", name="Cancel").click()
            dialog = page.get_by_role("dialog", name="Cancel Tour: Ground floor tour?")
            await expect(dialog).to_be_visible()
            await expect(dialog.get_by_role("button", name="Keep the task")).to_be_focused()
            await web.axe_check(page)
            await web.screenshot(page, "console-confirm-cancel")
            await dialog.get_by_role("button", name="Keep the task").click()
            await expect(dialog).to_have_count(0)
            assert (await http.get(f"/api/tasks/{task}")).json()["state"] == "queued"
            await page.keyboard.press("Escape")  # nothing open: nothing happens
            await row.get_by_role("button", name="Cancel").click()
            await dialog.get_by_role("button", name="Cancel Tour: Ground floor tour").click()
            await expect(dialog).to_have_count(0)
            finished = page.get_by_role("table", name="Finished tasks")
            await expect(finished.locator(f'tr[data-task="{task}"]')).to_contain_text(
                "cancelled by staff"
            )
            status = (await http.get(f"/api/tasks/{task}")).json()
            assert status["state"] == "cancelled"
            assert status["reason"].startswith("cancelled by staff")


async def test_cancelling_a_running_tour_from_the_robots_view_asks_and_gives_the_reason(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1, time_scale=4) as fleet:
        async with fleet.http() as http:
            watch = await open_page(fleet.admin_url)
            page = watch.page
            await web.sign_in(watch, web.operator_token)
            await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
            [task] = await request_tours(http, ["ground"])
            await web.open_view(page, "Robots")
            card = page.get_by_role("region", name="R1")
            await expect(card).to_contain_text("Tour: Ground floor tour", timeout=20_000)
            await card.get_by_role("button", name="Cancel R1's task").click()
            dialog = page.get_by_role("dialog", name="Cancel Tour: Ground floor tour?")
            await expect(dialog).to_contain_text("the visitor is told")
            await dialog.get_by_role("button", name="Cancel Tour: Ground floor tour").click()
            await expect(
                page.get_by_role("status").filter(has_text="Cancel Tour: Ground floor tour: done")
            ).to_be_visible()
            status = (await http.get(f"/api/tasks/{task}")).json()
            assert status["state"] == "cancelled"
            assert status["reason"] == "cancelled by staff (desk)"


async def test_a_snapshot_taken_before_a_robot_was_lost_does_not_bring_it_back(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        watch = await open_page("")
        page = watch.page
        hub = await LiveConnection.route(page)
        await page.goto(fleet.admin_url)
        await web.sign_in(watch, web.operator_token)
        await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
        fetched, release = asyncio.Event(), asyncio.Event()

        async def late_answer(route: Any) -> None:
            if fetched.is_set():  # only the reload this test holds back
                await route.continue_()
                return
            response = await route.fetch()  # R1 online, as the server says now
            robots = await response.json()
            for robot in robots:  # a mark the page can only have from this snapshot
                robot["out_of_service"] = True
            fetched.set()
            await release.wait()
            await route.fulfill(response=response, json=robots)

        await page.route("**/api/robots", late_answer)
        await hub.drop()  # the page reconnects and reloads its snapshot
        await fetched.wait()
        await fleet.kill("R1")
        await web.open_view(page, "Robots")
        heading = page.get_by_role("heading", name="R1")
        await expect(heading).to_contain_text("lost", timeout=20_000)
        release.set()
        # The late snapshot is drawn (its mark: R1 out of service), and R1 stays lost.
        await expect(heading).to_contain_text("out of service")
        await expect(heading).to_contain_text("lost")


async def test_event_log_names_places_and_shows_times_as_times(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """A node_reached row: the node by the site's name, the robot's time stamp as a time, not
    as a second ``at=`` of Unix seconds."""
    async with fleet_factory(robots=1) as fleet:
        async with fleet.http() as http:
            await request_tours(http, ["ground"])
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        await web.open_view(page, "Event log")
        reached = page.get_by_role("row").filter(has_text="node_reached").first
        await expect(reached).to_contain_text("reported=", timeout=30_000)
        text = await reached.inner_text()
        assert not re.search(r"=\d{9,}\.\d", text), text


async def test_a_running_tour_shows_the_stop_its_visitor_is_told(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The Tasks view says "stop N of M" from the task's own progress (what the visitor's phone
    says), never "at near ..." from the robot's place, at each stop of a whole tour."""
    async with fleet_factory(robots=1, time_scale=4, screens=True) as fleet:
        async with fleet.http() as http:
            watch = await open_page(fleet.admin_url)
            page = watch.page
            await web.sign_in(watch, web.operator_token)
            await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
            await web.open_view(page, "Tasks")
            [task] = await request_tours(http, ["highlights"])
            row = f'table[aria-label="Running tasks"] tr[data-task="{task}"]'
            cell = page.locator(f"{row} td").nth(3)
            await expect(cell).to_have_text("on the way to stop 1 of 3", timeout=30_000)
            shown = re.compile(r"^stop ([123]) of 3: (at .+|.+ explained, going on)$")
            row_text = f"() => document.querySelector('{row}')?.cells[3].textContent.trim() ?? null"
            text: str | None = "on the way to stop 1 of 3"
            seen = []
            while True:
                changed = await page.wait_for_function(
                    f"was => {{ const now = ({row_text})(); return now !== was && {{ now }}; }}",
                    arg=text,
                    timeout=60_000,
                )
                text = (await changed.json_value())["now"]
                if text is None:
                    break
                match = shown.match(text)
                assert match, text
                seen.append(int(match[1]))
                progress = (await http.get(f"/api/tasks/{task}")).json()["progress"]
                assert progress is None or progress["index"] >= seen[-1], (text, progress)
            assert seen and seen == sorted(seen) and seen[-1] == 3, seen
            assert (await http.get(f"/api/tasks/{task}")).json()["state"] == "done"


async def test_the_robots_view_says_where_the_tour_stands_as_the_tasks_view_does(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """Leaving a stop, R1 went on saying "at Roman mosaics (1/3)" (the last point it showed)
    all the way to the next one, standing elsewhere: it says the task's progress instead."""
    async with fleet_factory(robots=1, time_scale=4, screens=True) as fleet:
        async with fleet.http() as http:
            watch = await open_page(fleet.admin_url)
            page = watch.page
            await web.sign_in(watch, web.operator_token)
            await web.open_view(page, "Robots")
            card = page.get_by_role("region", name="R1")
            await expect(card).to_contain_text("online", timeout=20_000)
            await request_tours(http, ["highlights"])
            task_line = card.locator("dt", has_text="Task").locator(
                "xpath=following-sibling::dd[1]"
            )
            await expect(task_line).to_have_text(
                "Tour: Highlights, stop 1 of 3: Roman mosaics explained, going on", timeout=60_000
            )


async def test_the_event_log_filtered_by_a_robot_shows_the_rows_it_sent(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """A row a robot sent without naming itself (its call_elevator) was shown under the robot
    filter only for robots named "R<n>": a vehicle named V1 had none."""

    def with_v1(data: dict[str, Any]) -> None:
        data["robots"].append({"name": "V1", "token": "robot-V1-test-token", "start_node": "hall"})

    async with fleet_factory(robots=0, edit=with_v1) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        await web.open_view(page, "Event log")
        store = fleet.server.app.state.store
        for robot in ("V1", "R1"):
            store.record_event("call_elevator", robot, {"elevator": "lift", "floor": "F1"})
        events = page.get_by_role("table", name="Events")
        await expect(events.get_by_role("row").filter(has_text="call_elevator")).to_have_count(2)
        await page.get_by_role("combobox", name="Robot").select_option("V1")
        rows = events.get_by_role("row").filter(has_text="call_elevator")
        await expect(rows).to_have_count(1)
        await expect(rows).to_contain_text("V1")
