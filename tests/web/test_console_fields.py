"""The console's controls that send what a field beside them says (read by its id,
web/lib/dom.js ``inputValue``): the node a robot is sent to, a queued task's new priority and
the robot it is given to. The fleet is paused, so the tasks stay in the queue to be looked at."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import httpx
import pytest

pytestmark = [pytest.mark.browser, pytest.mark.timeout(300)]


def answered(page: Any, path: str) -> Any:
    """``async with answered(page, path) as reply``: the page's POST to ``path`` and its answer."""
    return page.expect_response(
        lambda r: r.request.method == "POST" and r.url.split("?")[0].endswith(path)
    )


async def task(http: httpx.AsyncClient, task_id: str) -> dict[str, Any]:
    reply = await http.get(f"/api/tasks/{task_id}")
    assert reply.status_code == 200, reply.text
    return dict(reply.json())


async def test_controls_send_what_their_fields_say(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet, fleet.http() as http:
        paused = await http.post("/api/fleet/pause", json={"reason": "fields test"})
        assert paused.status_code == 200, paused.text
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)

        await web.open_view(page, "Robots")
        nodes = page.get_by_label("Node for R1")
        node = await nodes.locator("option").nth(3).get_attribute("value")
        assert node
        await nodes.select_option(node)
        async with answered(page, "/api/tasks") as reply:
            await page.get_by_role("button", name="Send R1 to node").click()
        sent = await task(http, (await (await reply.value).json())["id"])
        assert (sent["kind"], sent["params"], sent["pinned_robot"]) == (
            "go_to",
            {"node": node},
            "R1",
        )

        created = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}})
        assert created.status_code in (200, 201), created.text
        tour = created.json()["id"]
        await web.open_view(page, "Tasks")
        row = page.locator(f'tr[data-task="{tour}"]')
        await row.get_by_role("spinbutton").fill("42")
        async with answered(page, f"/api/tasks/{tour}/priority"):
            await row.get_by_role("button", name="Set priority").click()
        await row.get_by_role("combobox").select_option("R1")
        async with answered(page, f"/api/tasks/{tour}/reassign"):
            await row.get_by_role("button", name="Reassign").click()
        shown = await task(http, tour)
        assert (shown["priority"], shown["pinned_robot"], shown["state"]) == (42, "R1", "queued")
