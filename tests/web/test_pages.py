"""The server side of the web pages: security headers, who-am-I, the map and plan images."""

from __future__ import annotations

import base64
import hashlib
import re
from pathlib import Path

import httpx

from backend.api.web import plan_file
from backend.settings import Settings, StaticToken
from backend.testing import running_server

ROOT = Path(__file__).resolve().parents[2]
SITE = ROOT / "sites" / "demo_museum.yaml"


def _settings(tmp_path: Path) -> Settings:
    return Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db",
        site=SITE,
        building_enabled=False,
        tokens=[StaticToken(token="panel-token-1", name="panel1", role="panel")],
    )


async def test_pages_have_a_csp_without_inline_scripts(tmp_path: Path) -> None:
    async with running_server(_settings(tmp_path)) as server, httpx.AsyncClient() as http:
        r = await http.get(f"{server.url}/admin/")
        assert r.status_code == 200
        policy = r.headers["content-security-policy"]
        script_src = re.search(r"script-src ([^;]*)", policy)
        assert script_src is not None
        assert "'unsafe-inline'" not in script_src.group(1)
        # The one inline block (the import map) is allowed by its hash, and nothing else is.
        [importmap] = re.findall(r'<script type="importmap">(.*?)</script>', r.text, re.S)
        digest = base64.b64encode(hashlib.sha256(importmap.encode()).digest()).decode()
        assert f"'sha256-{digest}'" in script_src.group(1)
        assert r.headers["x-content-type-options"] == "nosniff"
        js = await http.get(f"{server.url}/lib/hub.js")
        assert js.headers["content-type"].startswith("text/javascript")


async def test_me_map_and_plans_need_a_token_and_hide_secrets(tmp_path: Path) -> None:
    async with running_server(_settings(tmp_path)) as server, httpx.AsyncClient() as http:
        admin = {"Authorization": f"Bearer {server.admin_token}"}
        assert (await http.get(f"{server.url}/api/me")).status_code == 401
        me = await http.get(f"{server.url}/api/me", headers=admin)
        assert me.json() == {"name": "admin", "role": "admin"}
        panel = {"Authorization": "Bearer panel-token-1"}
        assert (await http.get(f"{server.url}/api/me", headers=panel)).json()["role"] == "panel"
        site = (await http.get(f"{server.url}/api/site/map", headers=panel)).json()["site"]
        assert site["robots"] and all("token" not in r for r in site["robots"])
        assert site["floors"][0]["plan_url"] == "/api/site/plans/F0"
        plan = await http.get(f"{server.url}/api/site/plans/F0", headers=panel)
        assert plan.status_code == 200
        assert plan.headers["content-type"] == "image/svg+xml"
        assert "script-src" not in plan.headers["content-security-policy"]
        assert plan.text.startswith("<svg")
        assert (await http.get(f"{server.url}/api/site/plans/F9", headers=panel)).status_code == 404
        assert (await http.get(f"{server.url}/api/site/plans/F0")).status_code == 401


def test_plan_images_stay_inside_the_site_folder(tmp_path: Path) -> None:
    (tmp_path / "site").mkdir()
    site_file = tmp_path / "site" / "site.yaml"
    (tmp_path / "secret.svg").write_text("<svg/>")
    (tmp_path / "site" / "ok.svg").write_text("<svg/>")
    (tmp_path / "site" / "notes.txt").write_text("x")
    assert plan_file(site_file, "ok.svg") == (tmp_path / "site" / "ok.svg").resolve()
    assert plan_file(site_file, "../secret.svg") is None
    assert plan_file(site_file, str(tmp_path / "secret.svg")) is None
    assert plan_file(site_file, "notes.txt") is None
    assert plan_file(site_file, "missing.svg") is None
    assert plan_file(None, "ok.svg") is None
