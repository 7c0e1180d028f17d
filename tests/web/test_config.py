"""The site editor (/config) in a real browser against a real server: the fair scenario end to
end, problems shown and publish refused, two editors, roll back, broken YAML, a new floor."""

from __future__ import annotations

import datetime as dt
import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from bench import reconfigure

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

ROOT = Path(__file__).resolve().parents[2]


async def open_editor(open_page: Any, fleet: Any) -> Any:
    watch = await open_page(f"{fleet.server.url}/config/")
    page = watch.page
    await page.get_by_label("Admin token").fill(fleet.server.admin_token)
    await page.get_by_label("Admin token").press("Enter")
    await page.get_by_label("Floor", exact=True).wait_for()
    return watch


async def test_fair_scenario_publishes_to_robots_and_the_tour_takes_the_new_route() -> None:
    result = await reconfigure._run(robots=2, time_scale=20.0)
    assert result["console_errors"] == []
    assert result["tour_followed_new_route"], result["goals"]
    assert result["robots"] == 2 and result["publish_to_robots_ms"] < 5000
    assert result["browser_seconds"] < 60


async def test_a_tour_naming_a_deleted_point_is_shown_and_publish_refused(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        watch = await open_editor(open_page, fleet)
        watch.expect_error(r"status of 422")
        page = watch.page
        await web.axe_check(page)
        await page.get_by_role("button", name="Points of interest").click()
        await page.get_by_role("button", name="Roman mosaics (mosaics)").click()
        await page.get_by_role("button", name="Delete point").click()
        problems = page.locator("#details ul.problems").first
        await expect(problems).to_contain_text("tours ground: points[1]")
        await expect(problems).to_contain_text("mosaics")
        await expect(page.locator("#problem-count")).to_contain_text("publishing is refused")
        # On the element: the tour's list marks the unknown point.
        await problems.get_by_role("button", name="tours ground: points[1]").click()
        await expect(page.locator("ol.tour-points li.has-issue")).to_contain_text(
            "unknown point mosaics"
        )
        await page.get_by_role("button", name="Publish", exact=True).click()
        await expect(page.get_by_role("alert").first).to_contain_text("Publish refused")
        await web.axe_check(page)
        await web.screenshot(page, "config-problems")
        async with fleet.http() as http:
            assert (await http.get("/api/site")).json()["version"] == 1
        # Undo brings the point back and the problems go.
        await page.keyboard.press("Control+z")
        await expect(page.locator("#problem-count")).to_have_text("No problems")


async def test_two_editors_one_is_refused_then_merges(fleet_factory: Any, open_page: Any) -> None:
    async with fleet_factory(robots=0) as fleet:
        alice = (await open_editor(open_page, fleet)).page
        bob_watch = await open_editor(open_page, fleet)
        bob_watch.expect_error(r"status of 409")
        bob = bob_watch.page
        for page in (alice, bob):
            await page.get_by_role("button", name="Tours").click()
        await alice.get_by_role("button", name="Highlights (highlights)").click()
        await alice.get_by_label("name", exact=True).fill("Best of the museum")
        await alice.get_by_label("name", exact=True).press("Enter")
        await alice.evaluate("guidebotProbe.saved()")
        await bob.get_by_role("button", name="First floor tour (upstairs)").click()
        await bob.get_by_role("button", name="Move Tapestries down").click()
        alert = bob.get_by_role("alert").filter(has_text="not saved")
        await expect(alert).to_contain_text("the draft was changed by admin")
        await bob.get_by_role("button", name="Merge my changes into it").click()
        await expect(alert).to_have_count(0)
        await bob.evaluate("guidebotProbe.saved()")
        async with fleet.http() as http:
            draft = (await http.get("/api/site/draft")).json()["draft"]
        tours = {t["id"]: t for t in draft["tours"]}
        assert tours["highlights"]["name"] == "Best of the museum"
        assert tours["upstairs"]["points"] == ["globes", "tapestries", "telescope"]


async def test_roll_back_restores_the_previous_tour_order(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        page = (await open_editor(open_page, fleet)).page
        await page.get_by_role("button", name="Tours").click()
        await page.get_by_role("button", name="Ground floor tour (ground)").click()
        first = page.locator("ol.tour-points li").first
        await first.focus()
        await page.keyboard.press("Alt+ArrowDown")  # keyboard reorder
        await expect(page.locator("ol.tour-points li").nth(1)).to_have_attribute(
            "data-point", "welcome"
        )
        await page.get_by_role("button", name="Publish", exact=True).click()
        await expect(page.locator("#rollout")).to_contain_text("reached its robot")
        async with fleet.http() as http:
            tours = (await http.get("/api/site")).json()["site"]["tours"]
            assert tours[0]["points"][:2] == ["mosaics", "welcome"]
            await page.get_by_role("button", name="Changes in version 2").click()
            await expect(page.get_by_role("list", name="Changes in version 2")).to_contain_text(
                "tours ground: points"
            )
            await web.screenshot(page, "config-history")
            await page.get_by_role("button", name="Roll back to version 1").click()
            confirm = page.get_by_role("dialog", name="Roll back to version 1?")
            await expect(confirm).to_be_visible()  # one click never rolls back
            await web.axe_check(page)
            await confirm.get_by_role("button", name="Keep the live version").click()
            await expect(confirm).to_have_count(0)
            versions = (await http.get("/api/site/versions")).json()
            assert [v["version"] for v in versions] == [2, 1]
            await page.get_by_role("button", name="Roll back to version 1").click()
            await confirm.get_by_role("button", name="Roll back to version 1").click()
            await expect(page.get_by_role("status").filter(has_text="Rolled back")).to_be_visible()
            tours = (await http.get("/api/site")).json()["site"]["tours"]
            assert tours[0]["points"] == ["welcome", "mosaics", "amphorae", "sword", "loom"]
            versions = (await http.get("/api/site/versions")).json()
            assert [v["version"] for v in versions] == [3, 2, 1]
        await expect(page.locator("ol.tour-points li").first).to_have_attribute(
            "data-point", "welcome"
        )
        await web.axe_check(page)


async def test_broken_yaml_import_lists_every_error_with_its_line(
    fleet_factory: Any, open_page: Any
) -> None:
    async with fleet_factory(robots=0) as fleet:
        watch = await open_editor(open_page, fleet)
        watch.expect_error(r"status of 422")
        page = watch.page
        broken = (
            "name: Broken\nfloors:\n  - {id: F0}\nnodes:\n  - {id: a, floor: F0, x: 0, y: 0}\n"
            "  - {id: b, floor: F9, x: 1, y: zero}\nedges:\n  - {a: a, b: nowhere}\n"
        )
        await page.get_by_label("Import YAML into the draft").set_input_files(
            files=[
                {"name": "broken.yaml", "mimeType": "application/yaml", "buffer": broken.encode()}
            ]
        )
        errors = page.get_by_role("list", name="Problems in the imported file")
        await expect(errors).to_contain_text("line 6: nodes[1].y")
        await expect(errors).to_contain_text("line 8: edges[0].b")
        await expect(page.get_by_role("alert").first).to_contain_text("broken.yaml refused")
        await expect(page.locator("#problem-count")).to_have_text("No problems")  # draft kept


async def test_a_file_imported_while_the_version_list_loads_is_answered(
    fleet_factory: Any, open_page: Any
) -> None:
    """The editor draws as soon as the draft arrives; a slow version list (a loaded server) must
    not leave its controls calling helpers that are not set up yet."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(f"{fleet.server.url}/config/")
        watch.expect_error(r"status of 422")
        page = watch.page
        held: list[Any] = []
        await page.route("**/api/site/versions", lambda route: held.append(route))
        await page.get_by_label("Admin token").fill(fleet.server.admin_token)
        await page.get_by_label("Admin token").press("Enter")
        await page.get_by_label("Import YAML into the draft").wait_for()
        await page.get_by_label("Import YAML into the draft").set_input_files(
            files=[{"name": "empty.yaml", "mimeType": "application/yaml", "buffer": b"name: [\n"}]
        )
        await expect(page.get_by_role("alert").first).to_contain_text("empty.yaml refused")
        assert held, "the version list was not held back"
        for route in held:
            await route.continue_()
        versions = page.get_by_role("table", name="Published versions")
        await expect(versions).to_contain_text("(live)")
        # When it was published: the date too, on the 24-hour clock (was "12:53:58 AM").
        async with fleet.http() as http:
            live = (await http.get("/api/site/versions")).json()[0]["published_at"]
        published = dt.datetime.fromtimestamp(live).astimezone()
        await expect(versions).to_contain_text(f"{published:%b} {published.day}, {published:%Y}")
        await expect(versions).not_to_contain_text(re.compile(r"\d [AP]M"))


async def _settled_point(page: Any, x: float, y: float) -> dict[str, float]:
    """The screen pixel of a site point once the map has stopped moving (the same over two
    animation frames): Leaflet's fit-to-floor animation and the calibration form's resize
    may still be moving the plan (a click 1.4 m off was seen on a loaded machine)."""
    point: dict[str, float] = await page.evaluate(
        """([x, y]) => new Promise((resolve) => {
          let last = null;
          const step = () => {
            const p = guidebotProbe.pointFor(x, y);
            if (last && p.x === last.x && p.y === last.y) resolve(p);
            else { last = p; requestAnimationFrame(() => requestAnimationFrame(step)); }
          };
          step();
        })""",
        [x, y],
    )
    return point


async def test_new_floor_with_plan_calibrated_published_and_planned_to(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        page = (await open_editor(open_page, fleet)).page
        await page.get_by_role("button", name="Floors").click()
        await page.get_by_role("button", name="Add floor").click()
        await page.get_by_label("Upload plan (PNG, JPEG or SVG)").set_input_files(
            str(ROOT / "sites" / "demo_museum" / "floor1.svg")
        )
        await expect(page.get_by_label("plan image")).to_have_value(
            __import__("re").compile(r"^uploads/[0-9a-f]{32}\.svg$")
        )
        await page.get_by_label("Floor", exact=True).select_option("F2")
        await expect(page.locator("#map img.leaflet-image-layer")).to_have_count(1)
        # Calibrate: two points 10 plan-metres apart at scale 20 are 200 px; call them 5 m.
        await page.get_by_role("button", name="Calibrate scale…").click()
        for x in (0.0, 10.0):
            point = await _settled_point(page, x, 0.0)
            await page.mouse.click(point["x"], point["y"])
        await page.get_by_label("Distance (m)").fill("5")
        await page.get_by_role("button", name="Apply calibration").click()
        calibrated = page.get_by_role("status").filter(has_text="calibrated")
        await expect(calibrated).to_contain_text("Floor F2 calibrated: ")
        scale = float(await page.get_by_label("scale px per m").input_value())  # the floor's form
        # A click is a pixel (about 1 %); on a loaded machine Leaflet's pan animation may still
        # be settling between the two clicks (41.7 seen): 10 % still tells 40 from 20 or 80.
        assert scale == pytest.approx(40, rel=0.1)
        await page.get_by_role("radio", name="Add node").click()
        point = await page.evaluate("guidebotProbe.pointFor(2, 2)")
        await page.mouse.click(point["x"], point["y"])
        await page.get_by_label("id", exact=True).fill("attic")
        await page.get_by_label("id", exact=True).press("Enter")
        # A point of interest on it, and the elevator now stops there.
        await page.get_by_role("button", name="Points of interest").click()
        await page.get_by_role("button", name="Add point").click()
        await page.get_by_label("node", exact=True).select_option("attic")
        await page.get_by_role("button", name="Elevators").click()
        await page.get_by_role("button", name="lift", exact=True).click()
        stops = await page.get_by_label("stops (JSON)").input_value()  # JSON.stringify's
        extra = (
            ',{"floor":"F2","node":"attic","call":{"module":"otb_first","point":"lift_call"},'
            '"in_position":{"module":"otb_first","point":"lift_here"}}]'
        )
        await page.get_by_label("stops (JSON)").fill(stops[:-1] + extra)
        await page.get_by_label("stops (JSON)").blur()
        await page.evaluate("guidebotProbe.saved()")
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        await web.screenshot(page, "config-new-floor")
        await page.get_by_role("button", name="Publish", exact=True).click()
        await expect(page.locator("#rollout")).to_contain_text("reached its robot")
        async with fleet.http() as http:
            floor = (await http.get("/api/site")).json()["site"]["floors"][-1]
            assert floor["scale_px_per_m"] == scale
            assert floor["plan_origin"] == pytest.approx([0, 0], abs=0.2)
            plan = await http.get("/api/site/plans/F2")
            assert plan.status_code == 200 and plan.content.startswith(b"<svg")
            path = await http.get(
                "/api/paths", params={"from_node": "entrance", "to_node": "attic"}
            )
            assert path.status_code == 200, path.text
            assert any(s.get("elevator") == "lift" for s in path.json()["steps"])
        await web.axe_check(page)


async def test_publish_after_a_save_that_failed_does_not_leave_the_change_out(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """An edit whose save failed (the server unreachable for a moment) is not in the shared
    draft: publishing then published the draft without it and said "Version 2 is live.", and
    the editor's copy took the published draft, so the change was gone without a word."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_editor(open_page, fleet)
        watch.expect_error(r"status of 503")
        page = watch.page

        async def unavailable(route: Any) -> None:
            if route.request.method == "PUT":
                await route.fulfill(status=503, json={"detail": "restarting"})
            else:
                await route.fallback()

        await page.route("**/api/site/draft", unavailable)
        await page.get_by_role("button", name="Tours").click()
        await page.get_by_role("button", name="Highlights (highlights)").click()
        await page.get_by_label("name", exact=True).fill("Best of the museum")
        await page.get_by_label("name", exact=True).press("Enter")
        await page.evaluate("guidebotProbe.saved()")
        await expect(page.locator("#draft-status")).to_contain_text("not saved")
        await page.get_by_role("button", name="Publish", exact=True).click()
        refused = page.get_by_role("alert").filter(has_text="Publish refused")
        await expect(refused).to_contain_text("your last change is not saved")
        await web.axe_check(page)
        async with fleet.http() as http:
            assert (await http.get("/api/site")).json()["version"] == 1
            # The server is back: Publish saves the change first, then publishes it.
            await page.unroute("**/api/site/draft", unavailable)
            await page.get_by_role("button", name="Publish", exact=True).click()
            await expect(page.locator(".notice.ok")).to_contain_text("Version 2 is live.")
            await expect(page.locator("#draft-status")).not_to_contain_text("not saved")
            site = (await http.get("/api/site")).json()
        assert site["version"] == 2
        tours = {t["id"]: t for t in site["site"]["tours"]}
        assert tours["highlights"]["name"] == "Best of the museum"


async def test_a_publish_note_goes_with_its_version_only(
    fleet_factory: Any, open_page: Any
) -> None:
    """The note stayed in the bar after publishing, so the next version went out with the last
    one's note ("rename welcome" on a version that changed a tour): the history lied."""
    async with fleet_factory(robots=0) as fleet:
        page = (await open_editor(open_page, fleet)).page
        await page.get_by_role("button", name="Points of interest").click()
        await page.get_by_role("button", name="Welcome hall (welcome)").click()
        await page.get_by_label("name", exact=True).fill("Welcome desk")
        await page.get_by_label("name", exact=True).press("Enter")
        note = page.get_by_label("Note")
        await note.fill("rename welcome")
        await page.get_by_role("button", name="Publish", exact=True).click()
        await expect(page.locator(".notice.ok")).to_contain_text("Version 2 is live.")
        await expect(note).to_have_value("")
        await page.get_by_role("button", name="Tours").click()
        await page.get_by_role("button", name="Ground floor tour (ground)").click()
        await page.locator("ol.tour-points li").first.focus()
        await page.keyboard.press("Alt+ArrowDown")
        await page.evaluate("guidebotProbe.saved()")
        await page.get_by_role("button", name="Publish", exact=True).click()
        await expect(page.locator(".notice.ok")).to_contain_text("Version 3 is live.")
        async with fleet.http() as http:
            versions = (await http.get("/api/site/versions")).json()
        notes = {v["version"]: v["note"] for v in versions}
        assert notes[2] == "rename welcome" and notes[3] == "", notes
