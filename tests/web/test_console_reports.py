"""The console's Reports view (docs/reports.md): a day's figures from a real run, charts drawn,
a figure downloaded as CSV, a bad range refused with the server's reason, the printed summary
on one page, and axe-core clean."""

from __future__ import annotations

import asyncio
import collections
import contextlib
import datetime as dt
import itertools
import json
import random
import re
import sqlite3
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from click.testing import CliRunner
from playwright.async_api import expect

from backend.reports.cli import replay_command
from bench.reports import venue_events

pytestmark = [pytest.mark.browser, pytest.mark.timeout(150)]


async def test_reports_view_charts_csv_errors_and_print(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        async with fleet.http() as http:
            # The tour waits in the queue: had R1 run it, it could end (its visitor gone after
            # the first stop) before the page looked for "no tour ended yet" below.
            (await http.post("/api/fleet/pause", json={"reason": "a report"})).raise_for_status()
            reply = await http.post(
                "/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}}
            )
            task = reply.json()
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        await web.open_view(page, "Reports")
        headline = page.get_by_role("definition").first  # "Tours requested"
        await expect(page.locator(".report-headline")).to_contain_text("Tours requested")
        await expect(headline).to_have_text("1", timeout=20_000)
        assert task["id"]
        # Both charts are drawn by the vendored uPlot.
        await expect(page.locator("#chart-tours canvas")).to_have_count(1)
        await expect(page.locator("#chart-waits canvas")).to_have_count(1)
        # Their time axes on the 24-hour clock, as every time on the console (uPlot's own
        # said "2pm"): the labels as drawn, which the canvas does not show a test.
        for chart in ("#chart-tours", "#chart-waits"):
            axis = page.locator(chart)
            await expect(axis).to_have_attribute("data-x-ticks", re.compile(r"\b\d\d:00\b"))
            ticks = await axis.get_attribute("data-x-ticks") or ""
            assert not re.search(r"\d(am|pm)\b", ticks), ticks
        await expect(page.get_by_role("table", name="Robots' time and distance")).to_contain_text(
            "R1"
        )
        # The three "stopped following" tables sit side by side without overlapping (each
        # table's "none" line used to take a grid cell of its own and push the next table
        # over its neighbour's last column), and no tour ended yet: each says so.
        boxes = []
        for by in ("Tour", "Language", "Stop"):
            block = page.locator(".report-table").filter(
                has=page.get_by_role("table", name=f"Stopped following per {by}")
            )
            await expect(block).to_contain_text("No tour ended in this period.")
            boxes.append(await block.bounding_box())
        for left, right in itertools.pairwise(boxes):
            assert left and right
            side_by_side = abs(left["y"] - right["y"]) < 1
            assert not side_by_side or left["x"] + left["width"] <= right["x"], boxes
        await web.axe_check(page)

        # A figure as CSV, with the operator's token (not a link anyone could open).
        asked = dt.datetime.now(dt.UTC)
        async with page.expect_download() as info:
            await page.get_by_role("button", name="CSV: tasks per hour").click()
        download = await info.value
        assert download.suggested_filename.startswith("guidebot-tasks-")
        saved = await download.path()
        text = await asyncio.to_thread(Path(saved).read_text, encoding="utf-8")
        lines = text.splitlines()
        assert lines[0] == "start,requested,done,failed,cancelled" and len(lines) == 25
        requested = [line.split(",")[1] for line in lines[1:]]
        assert sum(int(n) for n in requested if n) == 1
        # Today's hours to come have no counts yet (blank), not zero tours; those begun do.
        day = dt.date.fromisoformat(lines[1][:10])
        begun = {t.hour + 1 if t.date() == day else 24 for t in (asked, dt.datetime.now(dt.UTC))}
        counted = requested.index("") if "" in requested else 24
        assert counted in begun and set(requested[counted:]) <= {""}, (requested, begun)

        # A week, day by day: seven rows in the tasks CSV, and the chart redrawn.
        await page.get_by_label("Period", exact=True).select_option("week")
        await page.get_by_role("button", name="Show report").click()
        await expect(page.locator(".report-period")).to_contain_text("(")
        await expect(page.locator("#chart-tours canvas")).to_have_count(1)

        # A custom range that ends before it starts: the server's reason on the page.
        watch.expect_error(r"status of 422|HTTP 422 .*/api/reports\?")
        await page.get_by_label("Period", exact=True).select_option("range")
        await page.get_by_label("From").fill("2026-07-14T12:00")
        await page.get_by_label("Until").fill("2026-07-14T10:00")
        await page.get_by_role("button", name="Show report").click()
        await expect(
            page.get_by_role("alert").filter(has_text="ends before it starts")
        ).to_be_visible()

        # A file that is not a replay is refused, saying so.
        await page.get_by_label("Period", exact=True).select_option("day")
        await page.get_by_role("button", name="Show report").click()
        await page.get_by_label("Open a replay file").set_input_files(
            files=[{"name": "notes.json", "mimeType": "application/json", "buffer": b'{"a": 1}'}]
        )
        await expect(
            page.get_by_role("alert").filter(has_text="not a replay file written by guidebot")
        ).to_be_visible()

        # The daily summary, printed: the console's chrome and the form are left out.
        await page.get_by_label("Period", exact=True).select_option("day")
        await page.get_by_role("button", name="Show report").click()
        await expect(page.locator("#chart-tours canvas")).to_have_count(1)
        await page.emulate_media(media="print")
        await expect(page.locator("#tabs")).to_be_hidden()
        await expect(page.get_by_role("form", name="Report period")).to_be_hidden()
        await expect(page.locator(".report-headline")).to_be_visible()
        pdf = await page.pdf(format="A4", print_background=True)
        assert _pages(pdf) == 1, "the daily summary prints on one page"


def _pages(pdf: bytes) -> int:
    """The page count of a PDF Chromium wrote (its page tree's /Count)."""
    counts = [int(n) for n in re.findall(rb"/Count (\d+)", pdf)]
    return max(counts) if counts else 0


async def test_a_busy_days_summary_prints_on_one_page(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, tmp_path: Path, demo_site: Any
) -> None:
    """Yesterday as the reports bench writes a busy venue's day (eight robots, some 300 tours),
    in the server's own database, and ten robots walking the demo museum's ground floor: every
    part of the view filled, the busiest nodes on the floor plan, still one printed page; then
    the day played back and scrubbed end to end."""
    async with fleet_factory(robots=1) as fleet:
        yesterday = dt.datetime.now(dt.UTC).date() - dt.timedelta(days=1)
        # Named apart from the live fleet's R1: its connection today, logged before these rows,
        # would make yesterday's R1 events older than what the fold already knows of R1.
        rows = venue_events(yesterday, 8, random.Random(7), prefix="V")
        noon = dt.datetime(yesterday.year, yesterday.month, yesterday.day, 12, tzinfo=dt.UTC)
        walks = _walkers(demo_site, noon - dt.timedelta(hours=3), robots=10, hours=10)
        visits = collections.Counter(json.loads(row[3])["node"] for row in walks)
        [(busiest, _)], quietest = visits.most_common(1), min(visits, key=visits.__getitem__)
        rows += walks
        await asyncio.to_thread(_insert, tmp_path / "guidebot.db", rows)
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        await web.open_view(page, "Reports")
        await page.get_by_label("Day").fill(yesterday.isoformat())
        # The server's answer, however long a busy day's first fold takes on a loaded machine
        # (it outlasted expect's 5 s while the page said "Loading the report…"): the test's own
        # time-out is the guard.
        async with page.expect_response(
            lambda r: "/api/reports?" in r.url and yesterday.isoformat() in r.url, timeout=0
        ):
            await page.get_by_role("button", name="Show report").click()
        await expect(page.locator(".report-period")).to_contain_text(
            f"{yesterday.isoformat()} 00:00"
        )
        tours = sum(1 for row in rows if row[1] == "task_created" and b'"tour"' in row[3])
        headline = page.locator(".report-headline div").first
        await expect(headline).to_contain_text(str(tours))
        robots = page.get_by_role("table", name="Robots' time and distance")
        await expect(robots.locator("tbody tr")).to_have_count(18)  # the walkers: distance only
        # Rows by the names staff know: the tour's name, the language's name.
        per_tour = page.get_by_role("table", name="Stopped following per Tour")
        await expect(per_tour).to_contain_text("Highlights")
        await expect(per_tour).not_to_contain_text("highlights")
        per_language = page.get_by_role("table", name="Stopped following per Language")
        await expect(per_language).to_contain_text("Spanish")
        stops = page.get_by_role("table", name="Stops most listened to")
        await expect(stops.locator("tbody tr")).to_have_count(10)
        await expect(page.locator("#chart-tours canvas")).to_have_count(1)
        top = page.get_by_role("list", name="Busiest places").get_by_role("listitem")
        await expect(top.first).to_contain_text(f": {visits[busiest]}")
        most = page.locator(f'.heat-node[data-node="{busiest}"]')
        least = page.locator(f'.heat-node[data-node="{quietest}"]')
        assert await most.get_attribute("r") == "1"  # the biggest
        assert float(await least.get_attribute("r") or 1) < 1
        await web.axe_check(page)
        await web.screenshot(page, "console-reports")
        await page.get_by_role("heading", name="Busiest places").scroll_into_view_if_needed()
        await web.screenshot(page, "console-reports-heat")
        await page.emulate_media(media="print")
        pdf = await page.pdf(format="A4", print_background=True)
        assert _pages(pdf) == 1, "the daily summary prints on one page"
        await page.emulate_media(media="screen")

        # The day played back on the console's Leaflet floor map: at noon the walkers are on
        # the ground floor.
        await page.get_by_role("button", name="Replay this period").click()
        slider = page.get_by_label("Time", exact=True)
        await expect(page.locator("#replay-on-floor")).to_contain_text("On this floor")
        await slider.fill(str(int(noon.timestamp()) + 1))
        robot = page.locator('#replay-map .robot-marker[aria-label="robot W0"]')
        await expect(robot).to_have_count(1)
        await expect(page.locator("#replay-on-floor")).to_contain_text("W0, W1")
        await page.get_by_role("button", name="Play", exact=True).click()
        await expect(page.get_by_role("button", name="Pause", exact=True)).to_be_visible()
        await page.get_by_role("button", name="Pause", exact=True).click()
        await web.axe_check(page)
        await page.locator("#replay-map").scroll_into_view_if_needed()
        await web.screenshot(page, "console-reports-replay")
        # Scrubbed end to end in 180 painted frames, ten robots walking all day, the slider
        # moved a step a frame as a hand would move it: the frames a second the page kept
        # (reported; the display gives at most 60).
        frames = await slider.evaluate(
            """(slider) => new Promise((done) => {
                const [start, end] = [Number(slider.min), Number(slider.max)];
                let i = 0;
                let t0 = null;
                const step = (now) => {
                    t0 ??= now;
                    slider.value = String(Math.round(start + ((end - start) * i) / 180));
                    slider.dispatchEvent(new Event("input", { bubbles: true }));
                    i += 1;
                    if (i <= 180) requestAnimationFrame(step);
                    else done(180 / ((now - t0) / 1000));
                };
                requestAnimationFrame(step);
            })"""
        )
        walkers = page.locator("#replay-map .robot-marker")
        await expect(walkers).to_have_count(10)  # at 24:00 the ten walkers stand where they ended
        print(f"replay: a busy day scrubbed end to end at {frames:.0f} frames a second")

        # Noon to one written by `guidebot replay` and opened from the file: the walkers where
        # they stood at noon.
        saved = tmp_path / "noon.json"
        start, end = noon.isoformat(), (noon + dt.timedelta(hours=1)).isoformat()
        db_url = f"sqlite+aiosqlite:///{tmp_path}/guidebot.db"
        args = ["--from", db_url, "--start", start, "--end", end, "--out", str(saved)]
        result = await asyncio.to_thread(CliRunner().invoke, replay_command, args)
        assert result.exit_code == 0, result.output
        await page.get_by_label("Open a replay file").set_input_files(str(saved))
        await expect(page.get_by_text("Playing noon.json")).to_be_visible()
        await expect(walkers).to_have_count(10)


def _walkers(
    site: Any, start: dt.datetime, *, robots: int, hours: int
) -> list[tuple[float, str, str, bytes]]:
    """``robots`` robots walking the ground floor's corridors all day, a node every 20 s."""
    ground = {n.id for n in site.nodes if n.floor == site.floors[0].id}
    near: dict[str, list[str]] = {}
    for edge in site.edges:
        if edge.a in ground and edge.b in ground:
            near.setdefault(edge.a, []).append(edge.b)
            near.setdefault(edge.b, []).append(edge.a)
    rng = random.Random(3)
    rows = []
    for k in range(robots):
        name, node = f"W{k}", rng.choice(sorted(near))
        for step in range(hours * 180):
            node = rng.choice(near[node])
            data = json.dumps({"robot": name, "node": node}).encode()
            rows.append((start.timestamp() + 20 * step + k, "node_reached", name, data))
    return rows


def _insert(path: Path, rows: list[tuple[float, str, str, bytes]]) -> None:
    with contextlib.closing(sqlite3.connect(path)) as connection, connection:
        connection.executemany(
            "INSERT INTO events (at, kind, source, data) VALUES (?, ?, ?, ?)",
            [(at, kind, source, data.decode()) for at, kind, source, data in rows],
        )
