"""The staff console with two server processes on PostgreSQL and Redis: its header names the
process that serves it and the one that leads, and follows a fail-over."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from playwright.async_api import expect

from bench.servers import ADMIN_TOKEN, ServerProcess, wait_until
from tests.scale.conftest import pair, postgres, redis  # noqa: F401 (fixtures)

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


async def test_the_header_shows_which_process_leads_and_follows_a_fail_over(
    pair: list[ServerProcess],  # noqa: F811
    open_page: Any,
    web: SimpleNamespace,
) -> None:
    alpha, beta = pair
    watch = await open_page(f"{alpha.url}/admin/")
    await web.sign_in(watch, ADMIN_TOKEN)
    status = watch.page.locator("#server-status")
    await expect(status).to_contain_text("Process alpha leads · leader alpha (epoch 1)")
    await web.axe_check(watch.page)

    # The leader dies (its page loses the server); beta takes over, and a console on beta's
    # process says so.
    watch.expect_error(r"status of 50[23]|Failed to fetch|ERR_CONNECTION_(REFUSED|RESET)|WebSocket")
    alpha.kill()
    async with httpx.AsyncClient(base_url=beta.url) as http:
        await wait_until(
            lambda: _leads(http, "beta"), timeout=30, what="beta to serve after alpha's SIGKILL"
        )
    follower = await open_page(f"{beta.url}/admin/")
    await web.sign_in(follower, ADMIN_TOKEN)
    await expect(follower.page.locator("#server-status")).to_contain_text(
        "Process beta leads · leader beta (epoch 2)"
    )


async def _leads(http: httpx.AsyncClient, process: str) -> bool:
    cluster = (await http.get("/api/health")).json().get("cluster") or {}
    # Serving, not only leading: a leader whose components are still starting answers REST
    # with 503 (docs/scaling.md), and a sign-in then would fail.
    return bool(cluster.get("serving")) and cluster.get("process") == process
