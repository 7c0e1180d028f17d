"""The server builds every route before it serves: the first requests after a start (a site
publish, a robot's first call) do not build FastAPI's routes on the event loop."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import fastapi.routing
import httpx
import pytest

from backend.testing import running_server

from .conftest import GUI_TOKEN, server_settings


async def test_the_first_requests_find_every_route_built(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    built: list[str] = []
    build = fastapi.routing.get_dependant

    def counted(*args: Any, **kwargs: Any) -> Any:
        built.append(str(kwargs.get("path", "")))
        return build(*args, **kwargs)

    monkeypatch.setattr(fastapi.routing, "get_dependant", counted)
    async with running_server(server_settings(tmp_path)) as server:
        built.clear()  # what start-up built
        headers = {"Authorization": f"Bearer {GUI_TOKEN}"}
        async with httpx.AsyncClient(base_url=server.url, headers=headers) as http:
            assert (await http.get("/api/me")).status_code == 200
            assert (await http.get("/api/site/map")).status_code == 200
            assert (await http.get("/api/no-such-thing")).status_code == 404
    assert built == []
