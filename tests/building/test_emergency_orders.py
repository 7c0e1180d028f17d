"""The alarm's orders go out without one search of the site per robot: every robot's way to
safety comes from one table, searched when the server starts (on a 3000-node site, 20 searches
put 0.9-4 s between the alarm and the last robot's order: guidebot bench emergency)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import guidebot.site.emergency as site_emergency
from backend.testing import RunningServer
from tests.server.helpers import RobotStub

from .test_emergency import serving
from .test_server import demo_building


async def test_every_robot_is_ordered_from_one_search_made_before_the_alarm(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    searches: list[Any] = []
    search = site_emergency._to_safety

    def counted(*args: Any) -> Any:
        searches.append(args[1])
        return search(*args)

    monkeypatch.setattr(site_emergency, "_to_safety", counted)
    async with demo_building(tmp_path) as (_site, _sim, server):
        assert isinstance(server, RunningServer)
        async with serving(server) as http:
            hub = server.app.state.hub
            nodes = ["gb1", "corridor_w", "landing"]  # the site's three robots
            robots = [RobotStub(hub, f"R{i}", node) for i, node in enumerate(nodes, 1)]
            for robot in robots:
                robot.state()
            before = len(searches)
            declared = await http.post(
                "/api/emergency/declare", json={"zone": {}, "reason": "drill"}
            )
            assert declared.status_code == 200, declared.text
            orders = [await robot.wait_for("evacuate") for robot in robots]
            assert all(o.payload["safe_spot"] for o in orders), [o.payload for o in orders]
            assert orders[0].payload["path"][:2] == ["gb1", "gb2"]  # east: by the back gallery
            # A robot last seen next to a cabin may have got in since: the way from each of
            # the lift's landings comes with its order (docs/emergency.md); the others' not.
            assert orders[2].payload["landings"]["lift"]["F0"]["path"][0] == "lift0"
            assert orders[2].payload["landings"]["lift"]["F1"]["path"] == ["lift1", "landing"]
            assert orders[0].payload["landings"] == orders[1].payload["landings"] == {}
            assert len(searches) == before, "a search of the site per robot on the alarm's path"
