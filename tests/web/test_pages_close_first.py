"""The page fixture itself (tests/web/conftest.py): a test's pages close before the server they
show stops, whichever server it is and whenever it stops, so a page never logs reconnections
to a server that is gone (ERR_CONNECTION_REFUSED: test_building_modes failed so at teardown,
the robot's touch screen still open when the robot stopped)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from backend.settings import Settings
from backend.testing import running_server
from guidebot.site.schema import Site
from robot_agent.testing import light_robot

pytestmark = [pytest.mark.browser, pytest.mark.timeout(90)]


async def test_a_page_closes_before_the_robot_screen_it_shows_stops(
    fleet_factory: Any, open_page: Any, demo_site: Site
) -> None:
    robot = demo_site.robots[0]
    async with fleet_factory(robots=0) as fleet:
        console = await open_page(fleet.admin_url)
        async with light_robot(
            fleet.server.url,
            robot.name,
            robot.token,
            site=fleet.site_file,
            start_node=robot.start_node,
        ) as agent:
            assert agent.screen_server is not None
            screen = await open_page("", viewport=(1024, 600))
            async with screen.page.expect_websocket() as push:  # the screen's push channel
                await screen.page.goto(agent.screen_server.url)
            await push.value
        assert screen.page.is_closed()
        assert not console.page.is_closed()  # its server is still up


async def test_a_page_that_expects_its_server_to_go_stays_open(
    tmp_path: Path, open_page: Any
) -> None:
    settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", building_enabled=False)
    async with running_server(settings) as server:
        watch = await open_page(f"{server.url}/admin/")
        watch.expect_error(r"ERR_CONNECTION_REFUSED")  # it watches the server go and come back
    assert not watch.page.is_closed()
