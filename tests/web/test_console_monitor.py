"""The console's RoboGraph monitor in a real browser: a tour's net drawn as its PNML file draws
it, a net without graphics laid out in layers, labels that overlap nothing, zoom and pan, and
the live marking."""

from __future__ import annotations

import asyncio
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from petri_nets.builder import NetBuilder, message, timer, timer_elapsed
from petri_nets.pnml_writer import write_pnml

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

LABEL_BOXES = """svg => [...svg.querySelectorAll('text.label')].map(t => {
    const r = t.getBoundingClientRect();
    return {text: t.textContent, x: r.x, y: r.y, w: r.width, h: r.height};
})"""


def overlapping(boxes: list[dict[str, Any]]) -> list[tuple[str, str]]:
    """Pairs of labels whose boxes on the screen intersect."""
    pairs = []
    for i, a in enumerate(boxes):
        for b in boxes[i + 1 :]:
            if (
                a["x"] < b["x"] + b["w"]
                and b["x"] < a["x"] + a["w"]
                and a["y"] < b["y"] + b["h"]
                and b["y"] < a["y"] + a["h"]
            ):
                pairs.append((a["text"], b["text"]))
    return pairs


def two_point_tour(data: dict[str, Any]) -> None:
    data["tours"] += [{"id": "short", "name": "Short tour", "points": ["welcome", "mosaics"]}]


async def test_a_tour_net_is_drawn_from_its_pnml_file_with_no_label_over_another(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1, time_scale=2, edit=two_point_tour) as fleet:
        async with fleet.http() as http:
            structure = (await http.get("/api/nets/give_tour/structure")).json()
            reply = await http.post(
                "/api/tasks", json={"kind": "tour", "params": {"tour": "short"}, "robot": "R1"}
            )
            assert reply.status_code < 300, reply.text
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
        await web.open_view(page, "RoboGraph monitor")
        await page.get_by_label("Show the nets of").select_option("R1")
        net = page.get_by_role("region", name="Net give_tour")
        drawing = net.locator("svg.net")
        await expect(drawing).to_be_visible(timeout=20_000)

        boxes = await drawing.evaluate(LABEL_BOXES)
        names = {p["name"] for p in structure["places"]} | {
            t["name"] for t in structure["transitions"]
        }
        assert {b["text"] for b in boxes} == names
        assert overlapping(boxes) == []
        assert structure["layout"] == "pnml"
        await expect(drawing).to_have_attribute("data-layout", "pnml")
        # Every place sits where the file puts it (the drawing keeps the file's shape).
        centres = await drawing.evaluate(
            """svg => Object.fromEntries([...svg.querySelectorAll('[data-place] circle')].map(
                c => [c.parentNode.dataset.place, [c.cx.baseVal.value, c.cy.baseVal.value]]))"""
        )
        spread = float(await drawing.get_attribute("data-spread") or "0")
        assert spread == 1.0
        for place in structure["places"]:
            assert centres[place["id"]] == [place["x"], place["y"]], place["id"]

        # The live marking is drawn: a token moves as the tour runs.
        before = await net.locator("[data-place]").evaluate_all(
            "els => els.map(e => e.dataset.tokens).join(',')"
        )
        await page.wait_for_function(
            """before => {
                const net = document.querySelector('[aria-label="Net give_tour"]');
                if (!net) return true;  // ended: the marking certainly changed
                const now = [...net.querySelectorAll('[data-place]')].map(e => e.dataset.tokens);
                return now.join(',') !== before;
            }""",
            arg=before,
            timeout=30_000,
        )

        # Zoom and pan change the part shown; "Whole net" shows all of it.
        if await net.count():
            start = await drawing.get_attribute("viewBox")
            await net.get_by_role("button", name="Zoom in").click()
            zoomed = await drawing.get_attribute("viewBox")
            assert zoomed != start
            assert float(zoomed.split()[2]) < float(start.split()[2])  # type: ignore[union-attr]
            await drawing.focus()
            await page.keyboard.press("ArrowDown")
            panned = await drawing.get_attribute("viewBox")
            assert float(panned.split()[1]) > float(zoomed.split()[1])  # type: ignore[union-attr]
            box = await drawing.bounding_box()
            assert box is not None
            await page.mouse.move(box["x"] + 100, box["y"] + 100)
            await page.mouse.down()
            # A live update redraws the view mid-drag: the drag must survive it.
            await page.evaluate("() => window.guidebotProbe.redraw()")
            await page.mouse.move(box["x"] + 60, box["y"] + 40)
            await page.mouse.up()
            dragged = await drawing.get_attribute("viewBox")
            assert float(dragged.split()[0]) > float(panned.split()[0])  # type: ignore[union-attr]
            await net.get_by_role("button", name="Whole net").click()
            whole = await drawing.get_attribute("viewBox")
            assert float(whole.split()[3]) >= float(start.split()[3])  # type: ignore[union-attr]
            await drawing.scroll_into_view_if_needed()
            await web.screenshot(page, "monitor-tour")
            await net.get_by_role("button", name="Actual size").click()
            await expect(drawing).to_have_attribute("viewBox", start or "")
        await web.axe_check(page)


def plain_net(folder: Path) -> Path:
    """A net with long labels, a branch and a loop, written without any graphics (as a
    hand-written or foreign PNML file may be); it waits for a message that never comes."""
    b = NetBuilder("plain_tour", "A tour written without a drawing.")
    b.place("waiting_for_the_first_visitor_of_the_day", initial=1, action=timer(0.2))
    b.place("walking_to_the_next_exhibit_hall", action=timer(0.2))
    b.place("explaining_the_exhibit_in_great_detail")
    b.place("asking_whether_to_continue_the_tour")
    b.place("the_visitor_said_goodbye_and_left", final=True)
    b.transition(
        "a_visitor_arrives",
        ["waiting_for_the_first_visitor_of_the_day"],
        ["walking_to_the_next_exhibit_hall"],
        timer_elapsed(),
    )
    b.transition(
        "arrived_at_the_exhibit",
        ["walking_to_the_next_exhibit_hall"],
        ["explaining_the_exhibit_in_great_detail"],
        timer_elapsed(),
    )
    b.transition(
        "explanation_finished",
        ["explaining_the_exhibit_in_great_detail"],
        ["asking_whether_to_continue_the_tour"],
        message("never_published"),
    )
    b.transition(
        "yes_please_continue",
        ["asking_whether_to_continue_the_tour"],
        ["walking_to_the_next_exhibit_hall"],
        message("never_published"),
    )
    b.transition(
        "no_thank_you",
        ["asking_whether_to_continue_the_tour"],
        ["the_visitor_said_goodbye_and_left"],
        message("never_published"),
    )
    doc = b.build()
    for item in [*doc.places, *doc.transitions]:
        item.graphics = None
    path = folder / "plain_tour.pnml"
    path.write_bytes(write_pnml(doc))
    return path


async def test_a_net_without_a_drawing_is_laid_out_in_layers_with_no_label_over_another(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, tmp_path: Path
) -> None:
    async with fleet_factory(robots=0) as fleet:
        rgm = fleet.server.app.state.rgm
        rgm.library.add_file(plain_net(tmp_path))
        async with fleet.http() as http:
            structure = (await http.get("/api/nets/plain_tour/structure")).json()
        assert structure["layout"] == "layered"
        ys = {p["id"]: p["y"] for p in structure["places"]}
        # Layers follow the flow: each step of the tour lies below the one before.
        assert (
            ys["waiting_for_the_first_visitor_of_the_day"]
            < ys["walking_to_the_next_exhibit_hall"]
            < ys["explaining_the_exhibit_in_great_detail"]
            < ys["asking_whether_to_continue_the_tour"]
            < ys["the_visitor_said_goodbye_and_left"]
        )
        fleet.server.app.state.hub.endpoint("test").publish(
            "run_petri_net", {"net": "plain_tour"}, destination="rgm"
        )
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        await web.open_view(page, "RoboGraph monitor")
        await page.get_by_label("Show the nets of").select_option("rgm")
        net = page.get_by_role("region", name="Net plain_tour")
        drawing = net.locator("svg.net")
        await expect(drawing).to_have_attribute("data-layout", "layered", timeout=20_000)
        await expect(net).to_contain_text("Laid out in layers")
        # The marking moves on to the exhibit (two timers), and is drawn.
        await expect(
            net.locator('[data-place="explaining_the_exhibit_in_great_detail"]')
        ).to_have_attribute("data-tokens", "1", timeout=20_000)
        boxes = await drawing.evaluate(LABEL_BOXES)
        assert len(boxes) == 10
        assert overlapping(boxes) == []
        await web.axe_check(page)


async def test_the_monitor_opened_before_the_snapshot_shows_the_first_robot_online(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """Opened at once after signing in, before the robots had come, the monitor chose the
    server's own nets and said nothing ran there, with R1 online (CI, on a loaded machine)."""
    async with fleet_factory(robots=1) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        held: asyncio.Queue[Any] = asyncio.Queue()
        await page.route("**/api/robots", held.put_nowait)
        await web.sign_in(watch, web.operator_token)
        await web.open_view(page, "RoboGraph monitor")
        await expect(page.get_by_text("Loading the nets…")).to_be_visible()
        snapshot = await held.get()  # the console's snapshot asked for the robots: held
        await snapshot.continue_()
        await expect(page.get_by_role("region", name="Net waiting")).to_be_visible(timeout=20_000)
        await expect(page.get_by_label("Show the nets of")).to_have_value("R1")
        await expect(page.get_by_text("No net is running")).to_have_count(0)
