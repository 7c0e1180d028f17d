"""Every page says what the API says on a busy day (issue 33, "Checked"): three robots, two
visitors on their phones (each its own device) asking for tours and single points, staff
adding tours, re-prioritising and cancelling, a robot lost on the way; after every step each
phone's place in line, robot and meeting place equal GET /api/tasks/{id} as that device, and
the console's Robots view (link, mode), Alerts view (open alerts) and map markers equal
GET /api/robots and GET /api/alerts."""

from __future__ import annotations

import random
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from playwright.async_api import TimeoutError as PlaywrightTimeout
from playwright.async_api import expect

from guidebot.site.schema import Site

pytestmark = [pytest.mark.browser, pytest.mark.timeout(420)]

ROUNDS = 80
LOSE_ROBOT_AT = 55
"""The step at which R3's process dies (an alert, a robot lost, its tasks given up)."""
PANELS = {"panel-a-token": "panel-a", "panel-b-token": "panel-b"}
PHONE = (360, 740)
TOURS = ["ground", "upstairs", "highlights"]
FINAL = {"done", "failed", "cancelled"}
DEVICE_KEY = "localStorage.getItem('guidebot.visitor.device')"

VISITOR_VIEW = r"""() => {
  const box = document.querySelector(".request-state");
  if (!box) return null;
  const lines = [...box.querySelectorAll("p")].map((p) => p.textContent.trim());
  let number = null, place = null;
  const patterns = [/ is going to (.+?)(?:: there in about .*|\. Meet it there!)$/,
    / has arrived at (.+)\. Join it there!$/, /^Stop \d+ of \d+: (.+?)(?:, seen\.)?$/,
    / has shown you (.+)\. Thank you for your visit!$/];
  for (const line of lines) {
    const n = line.match(/^You are number (\d+) in line\.$/);
    if (n) number = Number(n[1]);
    for (const p of patterns) { const m = line.match(p); if (m) place = m[1]; }
  }
  const state = [...box.classList].find((c) => c !== "request-state") ?? "";
  return {state,
          robot: document.querySelector(".robot-name")?.textContent.trim() ?? "",
          number, place};
}"""

ROBOTS_VIEW = """() => [...document.querySelectorAll("section.robot-card")].map((card) => {
  const facts = Object.fromEntries([...card.querySelectorAll("dl.facts dt")].map(
    (dt) => [dt.textContent.trim(), dt.nextElementSibling.textContent.trim()]));
  return [card.querySelector("h3").id.slice("robot-".length),
          card.querySelector("h3 .badge").textContent.trim(), facts.Mode.split(",")[0]];
})"""

ALERTS_VIEW = """() => [...document.querySelectorAll('tr[data-state="open"]')]
  .map((tr) => tr.dataset.alert).sort()"""

MAP_VIEW = """() => ({floor: document.querySelector("#floor-select").value,
  robots: [...document.querySelectorAll('#map .leaflet-marker-icon[aria-label^="robot "]')]
    .map((m) => m.getAttribute("aria-label").slice(6)).sort()})"""


@dataclass
class Phone:
    """A visitor's phone: its page, its device id and the request it shows."""

    page: Any
    http: httpx.AsyncClient
    task: str | None = None


async def converge(page: Any, reader: str, api: Callable[[], Awaitable[Any]], what: str) -> int:
    """Wait until ``reader`` on the page gives what ``api`` says; the fleet moves on meanwhile,
    so each miss reads the API again (a page that stays wrong fails). Returns the reads."""
    expected = None
    for attempt in range(1, 16):
        expected = await api()
        try:
            await page.wait_for_function(
                f"e => JSON.stringify(({reader})()) === JSON.stringify(e)",
                arg=expected,
                timeout=3_000,
            )
            return attempt
        except PlaywrightTimeout:
            continue
    shown = await page.evaluate(reader)
    raise AssertionError(f"{what} never matched the API:\npage {shown}\napi  {expected}")


def visitor_expected(task: dict[str, Any], names: dict[str, str]) -> dict[str, Any]:
    """What the phone must show of a task: its state, robot, place in line, meeting place."""
    state, service, point = task["state"], task.get("service"), task["kind"] == "go_to_poi"
    progress = task.get("progress") or {}
    number = None
    if state == "queued" and service != "unavailable" and task.get("queue_position"):
        number = task["queue_position"]
    place = None
    if state in ("assigned", "running"):
        if point and service != "held_up":
            place = names[task["params"]["poi"]]
        elif not point and progress.get("index"):
            place = names[progress["poi"]]  # where the robot is, as the site names it
    elif state == "done" and point:
        place = names[task["params"]["poi"]]
    robot = f"Robot {task['robot']}" if task.get("robot") else ""
    return {"state": state, "robot": robot, "number": number, "place": place}


async def robots_api(http: httpx.AsyncClient) -> list[list[str]]:
    robots = (await http.get("/api/robots")).json()
    return sorted([r["name"], "online" if r["online"] else "lost", r["mode"]] for r in robots)


async def visitor_request(phone: Phone, rng: random.Random) -> None:
    """The visitor goes back to the start and asks for a random tour or point."""
    page = phone.page
    if phone.task is not None:
        await page.locator(".actions button").last.click()
    await expect(page.get_by_role("heading", name="Tours")).to_be_visible()
    cards = page.locator("article")
    card = cards.nth(rng.randrange(await cards.count()))
    async with page.expect_response(
        lambda r: r.url.endswith("/api/tasks") and r.request.method == "POST"
    ) as reply:
        await card.get_by_role("button").click()
    answer = await reply.value
    assert answer.status == 201, await answer.text()
    phone.task = (await answer.json())["id"]
    await expect(page.locator(".request-state")).to_be_visible()


async def test_every_view_follows_the_api_on_a_busy_day(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Site
) -> None:
    rng = random.Random(3333)
    names = {p.id: p.name or p.id for p in demo_site.pois}
    limits = {"task_requests_per_minute": 600.0, "task_request_burst": 100}
    async with fleet_factory(robots=3, time_scale=20, **limits) as fleet:
        for token, name in PANELS.items():
            fleet.server.app.state.tokens.add(token, name, "panel")
        phones = []
        for token in PANELS:
            page = (
                await open_page(f"{fleet.server.url}/visitor/#token={token}", viewport=PHONE)
            ).page
            await expect(page.get_by_role("heading", name="Tours")).to_be_visible()
            device = await page.evaluate(DEVICE_KEY)
            http = fleet.http(token)
            http.headers["X-Guidebot-Device"] = device
            phones.append(Phone(page, http))
        desk = await open_page(fleet.admin_url)
        console = desk.page
        await web.sign_in(desk, web.operator_token)
        reads: dict[str, list[int]] = {}
        seen: set[str] = set()
        """What the phones were told (to show the run was busy: in line, on the way...)."""
        async with fleet.http() as staff:
            for step in range(ROUNDS):
                if step == LOSE_ROBOT_AT:
                    await fleet.kill("R3")
                tasks = (await staff.get("/api/tasks", params={"limit": 300})).json()["tasks"]
                queued = [t["id"] for t in tasks if t["state"] == "queued"]
                live = [t["id"] for t in tasks if t["state"] not in FINAL]
                action = rng.random()
                if action < 0.4:
                    await visitor_request(rng.choice(phones), rng)
                elif action < 0.6 or not live:
                    body = {"kind": "tour", "params": {"tour": rng.choice(TOURS)}}
                    body["priority"] = rng.randint(0, 100)
                    reply = await staff.post("/api/tasks", json=body)
                    assert reply.status_code == 201, reply.text
                elif action < 0.85 and queued:
                    task = rng.choice(queued)
                    priority = {"priority": rng.randint(0, 100)}
                    reply = await staff.post(f"/api/tasks/{task}/priority", json=priority)
                    assert reply.status_code in (200, 409), (step, reply.text)
                else:
                    reply = await staff.post(f"/api/tasks/{rng.choice(live)}/cancel", json={})
                    assert reply.status_code in (200, 409), (step, reply.text)
                for phone in phones:
                    if phone.task is None:
                        continue

                    async def told(phone: Phone = phone) -> dict[str, Any]:
                        reply = await phone.http.get(f"/api/tasks/{phone.task}")
                        assert reply.status_code == 200, reply.text
                        shown = visitor_expected(reply.json(), names)
                        seen.add("in line" if shown["number"] else shown["state"])
                        seen.add("at a place" if shown["place"] else "")
                        return shown

                    reads.setdefault("phone", []).append(
                        await converge(phone.page, VISITOR_VIEW, told, "a phone")
                    )
                await web.open_view(console, "Robots")
                reads.setdefault("robots", []).append(
                    await converge(console, ROBOTS_VIEW, lambda: robots_api(staff), "Robots")
                )
                await web.open_view(console, "Alerts")

                async def open_alerts() -> list[str]:
                    alerts = sorted(a["id"] for a in (await staff.get("/api/alerts")).json())
                    seen.add("open alerts" if alerts else "")
                    return alerts

                reads.setdefault("alerts", []).append(
                    await converge(console, ALERTS_VIEW, open_alerts, "Alerts")
                )
                await web.open_view(console, "Map")
                floor = await console.locator("#floor-select").input_value()

                async def on_the_map(floor: str = floor) -> dict[str, Any]:
                    robots = (await staff.get("/api/robots")).json()
                    # A robot not online stays where it was last seen, labelled lost.
                    shown = [
                        r["name"] if r["online"] else f"{r['name']} (lost)"
                        for r in robots
                        if r["floor"] == floor and (r["online"] or r["last_seen"])
                    ]
                    return {"floor": floor, "robots": sorted(shown)}

                reads.setdefault("map", []).append(
                    await converge(console, MAP_VIEW, on_the_map, "the map")
                )
        for phone in phones:
            await phone.http.aclose()
        print(
            f"busy truth: {ROUNDS} steps; API reads until equal (max, count) "
            f"{ {k: (max(v), len(v)) for k, v in reads.items()} }; told {seen}"
        )
        assert {"in line", "at a place", "running", "open alerts"} <= seen, seen
