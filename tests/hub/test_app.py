"""The whole server as `guidebot server` builds it: every component, pages and API docs."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest
from click.testing import CliRunner

import backend.app
from backend.settings import Settings
from backend.testing import running_server
from guidebot.cli import main

ALL_COMPONENTS = list(backend.app.COMPONENTS)  # read before the hub_only fixture empties it


async def test_full_app_serves_health_docs_and_pages(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(backend.app, "COMPONENTS", ALL_COMPONENTS)  # undo hub_only
    assert ALL_COMPONENTS, "the server has components (Task Manager, ...)"
    settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/full.db")
    async with running_server(settings) as server, httpx.AsyncClient(base_url=server.url) as http:
        health = await http.get("/api/health")
        assert health.status_code == 200 and health.json()["status"] == "ok"
        assert "/api/health" in (await http.get("/openapi.json")).json()["paths"]
        assert (await http.get("/docs")).status_code == 200
        index = await http.get("/")
        assert index.status_code == 200 and 'href="/docs"' in index.text
        assert (await http.get("/no-such-page.html")).status_code == 404


def test_cli_lists_the_server_and_validates_its_flags() -> None:
    runner = CliRunner()
    assert "server" in runner.invoke(main, ["--help"]).output
    help_text = runner.invoke(main, ["server", "--help"]).output
    for flag in ("--host", "--port", "--db"):
        assert flag in help_text
    bad = runner.invoke(main, ["server", "--port", "70000"])
    assert bad.exit_code == 2 and "port" in bad.output
