"""A busy day in the console (issue 33, "Checked"): three robots, tours requested, re-prioritised
and cancelled round after round while the page is open; after every step the tasks view (queue
rows and positions, priorities, pinned robots; running tasks, their robots and states) comes to
what GET /api/tasks says."""

from __future__ import annotations

import random
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from playwright.async_api import TimeoutError as PlaywrightTimeout

pytestmark = [pytest.mark.browser, pytest.mark.timeout(300)]

ROUNDS = 60
TOURS = ["ground", "upstairs", "highlights"]
FINAL = {"done", "failed", "cancelled"}

PAGE_VIEW = """() => {
  const rows = (name) => [...document.querySelectorAll(`table[aria-label="${name}"] tbody tr`)];
  return {
    queue: rows("Queued tasks").map(tr => [tr.dataset.task, tr.cells[0].textContent.trim(),
      tr.cells[2].textContent.trim(), tr.cells[3].textContent.trim(),
      tr.querySelector('input[type=number]').value]),
    running: rows("Running tasks").map(tr => [tr.dataset.task, tr.cells[1].textContent.trim(),
      tr.cells[2].textContent.trim()]).sort(),
  };
}"""


async def api_view(http: httpx.AsyncClient) -> dict[str, Any]:
    tasks = (await http.get("/api/tasks", params={"limit": 300})).json()["tasks"]
    queue = [
        [
            t["id"],
            str(t["queue_position"]),
            str(t["priority"]),
            t["pinned_robot"] or "any",
            str(t["priority"]),  # the priority input of the row
        ]
        for t in tasks
        if t["state"] == "queued"
    ]
    running = sorted(
        [t["id"], t["robot"] or "—", t["state"]]
        for t in tasks
        if t["state"] != "queued" and t["state"] not in FINAL
    )
    return {"queue": queue, "running": running}


async def converge(page: Any, http: httpx.AsyncClient) -> int:
    """Wait until the page shows what the API says; the API moves on meanwhile (robots
    progress), so each miss reads it again. Returns how many reads it took."""
    for attempt in range(1, 20):
        expected = await api_view(http)
        try:
            await page.wait_for_function(
                f"e => JSON.stringify(({PAGE_VIEW})()) === JSON.stringify(e)",
                arg=expected,
                timeout=3_000,
            )
            return attempt
        except PlaywrightTimeout:
            continue
    shown = await page.evaluate(PAGE_VIEW)
    raise AssertionError(f"the tasks view never matched GET /api/tasks:\n{shown}\n{expected}")


async def test_busy_day_tasks_view_follows_the_api(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    rng = random.Random(33)
    async with fleet_factory(robots=3, time_scale=20) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        await web.open_view(page, "Tasks")
        reads = []
        async with fleet.http() as http:
            for step in range(ROUNDS):
                view = await api_view(http)
                queued = [row[0] for row in view["queue"]]
                action = rng.random()
                if action < 0.55 or not queued:
                    body = {"kind": "tour", "params": {"tour": rng.choice(TOURS)}}
                    body["priority"] = rng.randint(0, 100)
                    reply = await http.post("/api/tasks", json=body)
                elif action < 0.85:
                    task = rng.choice(queued)
                    priority = {"priority": rng.randint(0, 100)}
                    reply = await http.post(f"/api/tasks/{task}/priority", json=priority)
                else:
                    task = rng.choice(queued)
                    reply = await http.post(f"/api/tasks/{task}/cancel", json={})
                assert reply.status_code in (200, 201, 409), (step, reply.text)
                reads.append(await converge(page, http))
        print(f"busy day: {ROUNDS} steps, reads until equal: max {max(reads)}, {reads}")
