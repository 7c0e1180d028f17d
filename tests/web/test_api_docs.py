"""The API docs page (/docs): Swagger UI served by the server itself, so it renders offline."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx
import pytest
from playwright.async_api import expect

from backend.settings import Settings
from backend.testing import running_server
from tests.web.conftest import Pages

pytestmark = pytest.mark.browser

LOOPBACK = {"127.0.0.1"}


async def test_api_docs_render_with_nothing_loaded_from_outside(
    tmp_path: Path, open_page: Pages
) -> None:
    settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", building_enabled=False)
    async with running_server(settings) as server:
        async with httpx.AsyncClient() as http:
            docs = await http.get(f"{server.url}/docs")
            assert (await http.get(f"{server.url}/redoc")).status_code == 404  # not offered
        assert docs.status_code == 200
        script_src = re.search(r"script-src ([^;]*)", docs.headers["content-security-policy"])
        assert script_src is not None and "'unsafe-inline'" not in script_src.group(1)

        watch = await open_page("")
        outside: list[str] = []

        async def only_loopback(route: Any) -> None:
            if urlsplit(route.request.url).hostname in LOOPBACK:
                await route.continue_()
            else:  # the machine may be offline: any request elsewhere is a failure
                outside.append(route.request.url)
                await route.abort()

        await watch.page.context.route("**/*", only_loopback)
        await watch.page.goto(f"{server.url}/docs")
        # Every tag is listed, folded (with all of them open this Swagger UI drew only the
        # first nine operations once the API passed 128); a tag opens on a click.
        tags = watch.page.locator(".opblock-tag")
        tag_names = {
            op["tags"][0] for ops in server.app.openapi()["paths"].values() for op in ops.values()
        }
        await expect(tags).to_have_count(len(tag_names))
        operations = watch.page.locator(".opblock")
        for tag in ("server", "tasks", "bookings"):
            await watch.page.locator(f'.opblock-tag[data-tag="{tag}"]').click()
        health = watch.page.locator(".opblock-summary-path", has_text=re.compile("^/api/health$"))
        await expect(health).to_be_visible()
        await expect(
            watch.page.locator(".opblock-summary-path", has_text=re.compile("^/api/bookings$"))
        ).to_have_count(2)  # list and create
        assert await operations.count() > 10
        await expect(watch.page.locator(".info .title")).to_contain_text("GuideBot")
        assert outside == [], f"requests that left the server: {outside}"
