"""The RoboGraph editor (/nets/) in a real browser against a real server: open a library net,
add a place and an arc, see the engine's problem on its element and in the list, fix it, export
PNML that the reader takes back; operators read only."""

from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from click.testing import CliRunner
from playwright.async_api import expect

from petri_nets.cli import petri
from petri_nets.pnml import read_pnml
from petri_nets.trace import read_trace, replay
from petri_nets.validate import validate

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

ROOT = Path(__file__).resolve().parents[2]
PROBLEMS = re.compile(r"^\d+ problem\(s\)$")


async def open_editor(open_page: Any, fleet: Any, token: str) -> Any:
    watch = await open_page(f"{fleet.server.url}/nets/")
    page = watch.page
    await page.get_by_label("Staff token").fill(token)
    await page.get_by_label("Staff token").press("Enter")
    await page.get_by_label("Library net").wait_for()
    return watch


async def open_library_net(open_page: Any, fleet: Any, net: str, token: str = "") -> Any:
    """The editor's page signed in (the admin's token unless ``token``), ``net`` of the
    library opened."""
    page = (await open_editor(open_page, fleet, token or fleet.server.admin_token)).page
    await page.get_by_label("Library net").select_option(net)
    await page.get_by_role("button", name="Open", exact=True).click()
    return page


async def test_edit_a_library_net_see_a_problem_come_and_go_and_export_it(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, tmp_path: Path
) -> None:
    async with fleet_factory(robots=0) as fleet:
        page = await open_library_net(open_page, fleet, "explain_point")
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        canvas = page.locator("#canvas svg")
        await expect(canvas.locator("g.net-node")).to_have_count(10)
        await web.axe_check(page)
        # A new place, left of and above the first transition: its arc into it crosses no node
        # and no label (the screenshot nets-problem shows it).
        await page.get_by_role("button", name="Zoom out").click()  # room on the left
        await page.get_by_label("Add place").check()
        at = await page.evaluate(
            "[guidebotNets.model.doc.transitions[0].x, guidebotNets.model.doc.transitions[0].y]"
        )
        await click_at(page, at[0] - 100, at[1] - 60)
        new_place = canvas.locator('g[data-id="p1"]')
        await expect(new_place).to_be_visible()
        # An arc from it into the first transition: that transition can never fire now.
        first = await page.evaluate("guidebotNets.model.doc.transitions[0].id")
        await page.get_by_label("Add arc").check()
        await new_place.click()
        await canvas.locator(f'g[data-id="{first}"]').click()
        await expect(page.locator("#problem-count")).to_have_text(PROBLEMS)
        on_element = canvas.locator(f'g[data-id="{first}"]')
        await expect(on_element).to_have_class("net-node transition has-issue")
        await expect(page.locator("#problems")).to_contain_text("can never be enabled")
        await expect(page.locator("#problems")).to_contain_text(
            f"transition:{first}: transition {first} can never be enabled: input place(s) p1"
        )
        analyse = page.get_by_role("button", name="Analyse the reachability graph")
        await analyse.click()
        await expect(page.locator("#analysis")).to_contain_text(f"Never fire: {first}")
        await web.axe_check(page)
        await web.screenshot(page, "nets-problem")
        # Fixed: the new place starts marked.
        await page.get_by_label("Select and move").check()
        await new_place.click()
        await page.get_by_label("Initial tokens").fill("1")
        await page.get_by_label("Initial tokens").press("Enter")
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        await expect(on_element).not_to_have_class("net-node transition has-issue")
        # Undo brings the problem back, redo fixes it again.
        await page.get_by_role("button", name="Undo").click()
        await expect(page.locator("#problem-count")).to_have_text(PROBLEMS)
        await page.get_by_role("button", name="Redo").click()
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        await expect(page.locator("#analysis")).to_have_count(0)  # the net changed
        await analyse.click()
        await expect(page.locator("#analysis")).to_contain_text("Bounded: at most 1 token(s)")
        await expect(page.locator("#analysis")).to_contain_text("Every transition can fire.")
        # Export: the reader takes the file back, with the new place where it was drawn.
        async with page.expect_download() as download_info:
            await page.get_by_role("button", name="Export PNML").click()
        download = await download_info.value
        path = tmp_path / "explain_point.pnml"
        await download.save_as(path)
        doc, problems = read_pnml(path.read_bytes(), str(path))
        assert doc is not None and problems == []
        assert validate(doc) == []
        place = next(p for p in doc.places if p.id == "p1")
        assert place.initial == 1 and place.graphics is not None
        assert any(a.source == "p1" and a.target == first for a in doc.arcs)


async def test_an_operator_reads_a_net_without_editing_tools(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        page = await open_library_net(open_page, fleet, "give_tour", web.operator_token)
        await expect(page.locator("#canvas g.net-node").first).to_be_visible()
        await expect(page.get_by_text("Read only: your role may not publish nets.")).to_be_visible()
        await expect(page.get_by_label("Add place")).to_have_count(0)
        # The versions are there to read; publishing and restoring are not.
        await expect(page.get_by_role("heading", name="Versions of give_tour")).to_be_visible()
        await expect(page.get_by_role("button", name=re.compile("^Publish"))).to_have_count(0)
        await (
            page.locator("#lists")
            .get_by_role("button", name="give_tour (parameters, description)")
            .click()
        )
        await expect(page.get_by_label("Description")).to_be_disabled()
        await web.axe_check(page)


async def test_simulate_a_net_step_by_step_to_its_end(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, tmp_path: Path
) -> None:
    async with fleet_factory(robots=0) as fleet:
        page = await open_library_net(open_page, fleet, "explain_point")
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        await page.get_by_label("Parameters (JSON object)").fill('{"text": "Hello"}')
        await page.get_by_role("button", name="Run simulation").click()
        status = page.locator("#sim-status")
        await expect(status).to_contain_text("Step 0 of 5")
        start = page.locator('#canvas g[data-id="address_people"]')
        await expect(start).to_have_attribute("aria-label", re.compile(r"1 token\(s\)"))
        await page.get_by_role("button", name="Step", exact=True).click()
        await expect(status).to_contain_text("Step 1 of 5")
        await expect(status).to_contain_text("fired people_faced")
        await expect(start).not_to_have_attribute("aria-label", re.compile("token"))
        await expect(page.locator('#canvas g[data-id="people_faced"]')).to_have_class(
            re.compile(r"\bfired\b")
        )
        await expect(page.get_by_label("Messages of the simulation")).to_contain_text(
            "published face_people"
        )
        await web.axe_check(page)
        await web.screenshot(page, "nets-simulation")
        await page.get_by_role("button", name="To the end").click()
        await expect(status).to_contain_text("outcome done")
        await expect(page.locator('#canvas g[data-id="explained"]')).to_have_attribute(
            "aria-label", re.compile(r"1 token\(s\)")
        )
        await expect(page.get_by_label("Messages of the simulation")).to_contain_text('"Hello"')
        async with page.expect_download() as download_info:
            await page.get_by_role("button", name="Download trace").click()
        path = tmp_path / "trace.jsonl"
        await (await download_info.value).save_as(path)
        assert replay(read_trace(path))["explain_point#run"] == {"explained": 1}


async def screen_point(page: Any, x: float, y: float) -> dict[str, float]:
    """Where the drawing's point (x, y) (its own units) is on the page."""
    return await page.evaluate(  # type: ignore[no-any-return]
        """([x, y]) => {
          const svg = document.querySelector('#canvas svg');
          const m = svg.getScreenCTM();
          return {x: m.a * x + m.e, y: m.d * y + m.f};
        }""",
        [x, y],
    )


async def click_at(page: Any, x: float, y: float) -> None:
    """A click on the drawing at (x, y) of the drawing's own units."""
    point = await screen_point(page, x, y)
    await page.mouse.click(point["x"], point["y"])


async def test_draw_a_net_from_nothing_simulate_it_and_run_the_saved_file(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, tmp_path: Path
) -> None:
    async with fleet_factory(robots=0) as fleet:
        page = (await open_editor(open_page, fleet, fleet.server.admin_token)).page
        await page.get_by_role("button", name="New net").click()
        await page.get_by_label("Net id").fill("hello")
        await page.get_by_label("Net id").press("Enter")
        canvas = page.locator("#canvas svg")
        count = page.locator("#problem-count")
        await page.get_by_label("Add place").check()
        await click_at(page, 100, 100)
        await click_at(page, 100, 260)
        await page.get_by_label("Add transition").check()
        await click_at(page, 100, 180)
        await expect(canvas.locator("g.net-node")).to_have_count(3)
        # A transition with no input: the engine's problem, on it.
        t1 = canvas.locator('g[data-id="t1"]')
        await expect(t1).to_have_class(re.compile(r"\bhas-issue\b"))
        await expect(page.locator("#problems")).to_contain_text("t1 has no input place")
        await page.get_by_label("Add arc").check()
        await canvas.locator('g[data-id="p1"]').click()
        await t1.click()
        await t1.click()
        await canvas.locator('g[data-id="p2"]').click()
        await expect(page.locator("#problems")).not_to_contain_text("t1 has no input place")
        await expect(page.locator("#problems")).to_contain_text(
            "transition t1 can never be enabled: input place(s) p1 can never be marked"
        )
        # The start is marked, the end is final; the transition says something first.
        await page.get_by_label("Select and move").check()
        await canvas.locator('g[data-id="p1"]').click()
        await page.get_by_label("Initial tokens").fill("1")
        await page.get_by_label("Initial tokens").press("Enter")
        await expect(t1).not_to_have_class(re.compile(r"\bhas-issue\b"))
        await page.get_by_label("Action").select_option("publish")
        await page.get_by_label("Message type").select_option("say")
        await page.get_by_label("Payload (JSON").fill('{"text": "Hello, visitors"}')
        await page.get_by_label("Payload (JSON").press("Tab")
        await canvas.locator('g[data-id="t1"]').click()
        await page.get_by_label("Condition").select_option("message")
        await page.get_by_label("Message type").select_option("speech_ended")
        await canvas.locator('g[data-id="p2"]').click()
        await page.get_by_label("Final place").check()
        await expect(count).to_have_text("No problems")
        await web.axe_check(page)
        # A bend in the arc p1 -> t1: double-click it, drag the bend aside.
        await page.get_by_label("Select and move").check()
        middle = await screen_point(page, 100, 150)
        await page.mouse.dblclick(middle["x"], middle["y"])
        bend = canvas.locator('g[data-arc="a1"] rect.bend')
        await expect(bend).to_have_count(1)
        aside = await screen_point(page, 160, 140)
        await page.mouse.move(middle["x"], middle["y"])
        await page.mouse.down()
        await page.mouse.move(aside["x"], aside["y"], steps=4)
        await page.mouse.up()
        await expect(page.locator("#details")).to_contain_text("Bend points: (160, 140)")
        # Simulated to its end.
        await page.get_by_role("button", name="Run simulation").click()
        await page.get_by_role("button", name="To the end").click()
        await expect(page.locator("#sim-status")).to_contain_text("outcome done")
        await expect(page.get_by_label("Messages of the simulation")).to_contain_text(
            "published say"
        )
        # Saved, and run by `guidebot petri run` as it is.
        async with page.expect_download() as download_info:
            await page.get_by_role("button", name="Export PNML").click()
        download = await download_info.value
        assert download.suggested_filename == "hello.pnml"
        path = tmp_path / "hello.pnml"
        await download.save_as(path)
        result = CliRunner().invoke(petri, ["run", str(path), "--json"])
        assert result.exit_code == 0, result.output
        outcome = json.loads(result.output.strip().splitlines()[-1])
        assert outcome["outcome"] == "done" and outcome["final_marking"] == {"p2": 1}
        assert outcome["published"] == ["say"]
        doc, _ = read_pnml(path.read_bytes(), str(path))
        assert doc is not None
        arc = next(a for a in doc.arcs if a.source == "p1")
        assert arc.graphics is not None
        assert [(p.attrib["x"], p.attrib["y"]) for p in arc.graphics.findall("position")] == [
            ("160", "140")
        ]


async def test_a_pnml_file_from_another_tool_opens_with_its_drawing(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    woped = ROOT / "tests" / "petri" / "foreign" / "woped_claim.pnml"
    async with fleet_factory(robots=0) as fleet:
        watch = await open_editor(open_page, fleet, fleet.server.admin_token)
        page = watch.page
        await page.get_by_label("Open a PNML file").set_input_files(str(woped))
        await expect(page.locator("#notices")).to_contain_text("woped_claim.pnml opened")
        p1 = page.locator('#canvas g[data-id="p1"] circle:not(.token)')
        await expect(p1).to_have_attribute("cx", "60")
        await expect(p1).to_have_attribute("cy", "120")
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        # A file that is not a net: refused, with the reader's words.
        watch.expect_error(r"status of 422")
        await page.get_by_label("Open a PNML file").set_input_files(
            files=[{"name": "broken.pnml", "mimeType": "application/xml", "buffer": b"<pnml><net>"}]
        )
        await expect(page.get_by_role("alert")).to_contain_text("broken.pnml cannot be opened")
        await expect(page.get_by_role("alert")).to_contain_text("upload.pnml:1:")
        await web.axe_check(page)


async def test_select_several_copy_paste_move_and_delete_them_together(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        page = await open_library_net(open_page, fleet, "navigate_to_point")
        canvas = page.locator("#canvas svg")
        await expect(canvas.locator("g.net-node")).to_have_count(5)
        await canvas.locator('g[data-id="navigate"]').click()
        await canvas.locator('g[data-id="goal_reached"]').click(modifiers=["Shift"])
        await expect(canvas.locator("g.net-node.selected")).to_have_count(2)
        await page.get_by_role("button", name="Copy", exact=True).click()
        await page.get_by_role("button", name="Paste", exact=True).click()
        await expect(canvas.locator("g.net-node")).to_have_count(7)
        await expect(page.locator("#notices")).to_contain_text("2 node(s) pasted")
        doc = await page.evaluate("guidebotNets.model.doc")
        new = {p["id"] for p in doc["places"]} | {t["id"] for t in doc["transitions"]}
        new -= {"navigate", "arrived", "failed", "goal_reached", "navigation_failed"}
        assert len(new) == 2
        # The arc between the two came along; the pasted pair is selected and moves together.
        assert [a for a in doc["arcs"] if a["source"] in new and a["target"] in new]
        pasted = await page.evaluate(
            "[...guidebotNets.group].map(id => guidebotNets.model.node(id)).map(n => [n.x, n.y])"
        )
        first = canvas.locator(f'g[data-id="{sorted(new)[0]}"]')
        box = await first.bounding_box()
        assert box is not None
        await page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        await page.mouse.down()
        await page.mouse.move(box["x"] + 100, box["y"] + 60, steps=5)
        await page.mouse.up()
        moved = await page.evaluate(
            "[...guidebotNets.group].map(id => guidebotNets.model.node(id)).map(n => [n.x, n.y])"
        )
        shifts = {(m[0] - p[0], m[1] - p[1]) for m, p in zip(moved, pasted, strict=True)}
        assert len(shifts) == 1 and shifts != {(0, 0)}
        await page.get_by_role("button", name="Delete 2 nodes").click()
        await expect(canvas.locator("g.net-node")).to_have_count(5)
        await page.keyboard.press("Control+z")
        await expect(canvas.locator("g.net-node")).to_have_count(7)
        await page.get_by_role("button", name="Zoom in").click()
        await page.get_by_role("button", name="Fit").click()
        await web.axe_check(page)


async def test_a_rubber_band_selects_the_nodes_inside_it(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        page = await open_library_net(open_page, fleet, "navigate_to_point")
        canvas = page.locator("#canvas svg")
        await expect(canvas.locator("g.net-node")).to_have_count(5)
        doc = await page.evaluate("guidebotNets.model.doc")
        nodes = {n["id"]: (n["x"], n["y"]) for n in doc["places"] + doc["transitions"]}
        # A band over the upper part of the drawing: down to the transitions' row.
        row = nodes["goal_reached"][1]
        xs = [x for x, _ in nodes.values()]
        corner = await screen_point(page, min(xs) - 30, min(y for _, y in nodes.values()) - 30)
        other = await screen_point(page, max(xs) + 30, row + 5)
        inside = {n for n, (_, y) in nodes.items() if y <= row + 5}
        assert 1 < len(inside) < len(nodes)
        await page.keyboard.down("Shift")
        await page.mouse.move(corner["x"], corner["y"])
        await page.mouse.down()
        await page.mouse.move(other["x"], other["y"], steps=5)
        await expect(canvas.locator("rect.band")).to_be_visible()
        await page.mouse.up()
        await page.keyboard.up("Shift")
        await expect(canvas.locator("rect.band")).to_have_count(0)
        selected = canvas.locator("g.net-node.selected")
        await expect(selected).to_have_count(len(inside))
        assert {await g.get_attribute("data-id") for g in await selected.all()} == inside
        await expect(page.locator("#notices")).to_contain_text(f"{len(inside)} node(s) selected")
        await page.get_by_role("button", name=f"Delete {len(inside)} nodes").click()
        await expect(canvas.locator("g.net-node")).to_have_count(len(nodes) - len(inside))
        await web.axe_check(page)


async def test_choose_each_reply_while_simulating(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        page = await open_library_net(open_page, fleet, "explain_point")
        await page.get_by_label("Parameters (JSON object)").fill('{"text": "Hello"}')
        await page.get_by_label("Choose each reply myself").check()
        await page.get_by_role("button", name="Run simulation").click()
        waiting = page.get_by_role("group", name=re.compile("The net waits"))
        await expect(waiting).to_contain_text("people_faced (face_people: people_faced)")
        # No visitor turns up: time passes to face_people's time-out, and it goes on.
        await waiting.get_by_role("button", name="Let time pass to 10.0 s").click()
        await expect(waiting).to_contain_text("The net waits (at 10.0 s)")
        await expect(waiting).to_contain_text("speech_ended (explain_point: text_spoken)")
        synthesize = page.locator('#canvas g[data-id="synthesize_text"]')
        await expect(synthesize).to_have_attribute("aria-label", re.compile(r"1 token\(s\)"))
        await web.axe_check(page)
        await waiting.get_by_role("button", name=re.compile("^speech_ended")).click()
        # rest_expression waits for each servo: answered one by one, in any order.
        servo = waiting.get_by_role("button", name=re.compile("^servo_in_position"))
        await expect(servo).to_have_count(3)
        for left in (2, 1):
            await servo.last.click()
            await expect(servo).to_have_count(left)
        await servo.click()
        await expect(page.locator("#sim-status")).to_contain_text("outcome done")
        await expect(waiting).to_have_count(0)
        await expect(page.locator("#notices")).to_contain_text("outcome done")
