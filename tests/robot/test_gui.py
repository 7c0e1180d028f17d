"""The touch screen over a real uvicorn on 127.0.0.1 (port 0): requests, the question, events."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import httpx
import pytest
from websockets.asyncio.client import connect

from guidebot.bus import Bus
from robot_agent.clock import Clock
from robot_agent.gui import OnboardScreen, ScreenServer


@dataclass
class Screen:
    bus: Bus
    screen: OnboardScreen
    server: ScreenServer
    seen: Any


@pytest.fixture
async def screen(helpers: Any) -> AsyncIterator[Screen]:
    bus = Bus()
    seen = helpers.Recorder(bus.endpoint("t"), "task_request", "continue_answer")
    tours = [{"id": "ground", "name": "Ground floor tour", "points": ["welcome"]}]
    pois = [{"id": "welcome", "name": "Welcome hall", "node": "hall"}]
    onboard = OnboardScreen(bus.endpoint("screen"), Clock(10.0), "R1", tours=tours, pois=pois)
    await onboard.start()
    server = ScreenServer(onboard, port=0)
    await server.start()
    assert server.port != 0
    yield Screen(bus, onboard, server, seen)
    await server.stop()
    await onboard.stop()


async def test_page_and_menu(screen: Screen) -> None:
    async with httpx.AsyncClient(base_url=screen.server.url) as http:
        page = await http.get("/")
        assert page.status_code == 200 and "GuideBot" in page.text
        menu = (await http.get("/api/screen")).json()
    assert menu["robot"] == "R1"
    assert [t["id"] for t in menu["tours"]] == ["ground"]
    assert menu["question"] is None


async def test_tour_request_becomes_a_task_request(screen: Screen) -> None:
    async with httpx.AsyncClient(base_url=screen.server.url) as http:
        ok = await http.post("/api/request", json={"kind": "tour", "tour": "ground"})
        unknown = await http.post("/api/request", json={"kind": "tour", "tour": "attic"})
        malformed = await http.post("/api/request", json={"kind": "dance"})
    assert ok.status_code == 202
    assert unknown.status_code == 422 and "attic" in unknown.json()["detail"]
    assert malformed.status_code == 422
    [request] = screen.seen.of("task_request")  # the bad ones sent nothing
    assert request.payload == {
        "kind": "tour",
        "params": {"tour": "ground"},
        "priority": 5,
        "requester": "R1",
    }


async def test_continue_question_answer_and_timeout(screen: Screen) -> None:
    net = screen.bus.endpoint("net")
    async with (
        httpx.AsyncClient(base_url=screen.server.url) as http,
        connect(screen.server.url.replace("http", "ws") + "/ws") as ws,
    ):
        first = json.loads(await ws.recv())
        assert first["kind"] == "screen"
        assert (await http.post("/api/answer", json={"answer": "yes"})).status_code == 409
        ask = net.publish("ask_continue", {"question": "Go on?", "timeout_s": 600})
        event = json.loads(await ws.recv())
        assert event["kind"] == "ask_continue" and event["data"]["question"] == "Go on?"
        assert (await http.post("/api/answer", json={"answer": "yes"})).status_code == 200
        answer = screen.seen.of("continue_answer")[0]
        assert answer.payload == {"answer": "yes"} and answer.correlation_id == ask.id
        # Nobody answers: after timeout_s of robot time (10x faster here) "timeout" is sent.
        net.publish("ask_continue", {"question": "Still there?", "timeout_s": 2})
        await screen.seen.wait_for(lambda: len(screen.seen.of("continue_answer")) == 2)
        assert screen.seen.of("continue_answer")[1].payload == {"answer": "timeout"}


async def test_demo_visitor_answers_by_itself(helpers: Any) -> None:
    bus = Bus()
    seen = helpers.Recorder(bus.endpoint("t"), "continue_answer")
    onboard = OnboardScreen(bus.endpoint("screen"), Clock(20.0), "R1", auto_answer="yes")
    await onboard.start()
    ask = bus.endpoint("net").publish("ask_continue", {"question": "Go on?", "timeout_s": 600})
    await seen.wait_for(lambda: seen.of("continue_answer"))
    [answer] = seen.of("continue_answer")
    assert answer.payload == {"answer": "yes"} and answer.correlation_id == ask.id
    await onboard.stop()


async def test_a_refused_assignment_leaves_the_running_tour_on_the_screen(screen: Screen) -> None:
    server = screen.bus.endpoint("server")
    server.publish("task_assigned", {"task_id": "t1", "robot": "R1", "net": "give_tour"})
    server.publish("task_assigned", {"task_id": "t2", "robot": "R1", "net": "give_tour"})
    assert screen.screen.screen()["task"]["id"] == "t1"
    refused = {"task_id": "t2", "robot": "R1", "outcome": "refused", "reason": "robot busy"}
    robot = screen.bus.endpoint("robot-tasks")
    robot.publish("task_ended", refused)
    assert screen.screen.screen()["task"]["id"] == "t1"
    robot.publish("task_ended", {"task_id": "t1", "robot": "R1"})
    assert screen.screen.screen()["task"] is None


async def test_a_fire_alarm_holds_the_screen_in_the_requests_language(screen: Screen) -> None:
    """emergency_changed (then the robot's own evacuation_state) makes the evacuation screen;
    a request meanwhile is refused with the site's words in its language, like the server's
    503 (docs/visitor.md, "The robot's touch screen")."""
    server = screen.bus.endpoint("server")
    words = {"en": "Fire alarm. Leave the building.", "es": "Alarma de incendio. Salga."}
    server.publish("emergency_changed", {"state": "alarm", "zones": [{}], "words": words})
    screen.bus.endpoint("evacuation").publish("evacuation_state", {"state": "moving"})
    async with httpx.AsyncClient(base_url=screen.server.url) as http:
        shown = (await http.get("/api/screen?lang=es")).json()["alarm"]
        assert shown == {"words": "Alarma de incendio. Salga.", "evacuation": "moving"}
        refused = await http.post(
            "/api/request", json={"kind": "tour", "tour": "ground", "lang": "es"}
        )
        assert refused.status_code == 503
        assert refused.json() == {"detail": "Alarma de incendio. Salga.", "reason": "emergency"}
        assert not screen.seen.of("task_request")
        server.publish("emergency_changed", {"state": "normal"})
        assert (await http.get("/api/screen")).json()["alarm"] is None
        accepted = await http.post("/api/request", json={"kind": "tour", "tour": "ground"})
        assert accepted.status_code == 202
