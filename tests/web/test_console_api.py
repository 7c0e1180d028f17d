"""The console's REST endpoints without a browser: refusals say why and change nothing."""

from __future__ import annotations

from pathlib import Path

import httpx

from backend.settings import Settings, StaticToken
from backend.testing import running_server

ROOT = Path(__file__).resolve().parents[2]
SITE = ROOT / "sites" / "demo_museum.yaml"


async def test_console_endpoints_refuse_clearly(tmp_path: Path) -> None:
    settings = Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db",
        site=SITE,
        building_enabled=False,
        tokens=[StaticToken(token="operator-token-1", name="desk", role="operator")],
    )
    async with running_server(settings) as server:
        admin = {"Authorization": f"Bearer {server.admin_token}"}
        desk = {"Authorization": "Bearer operator-token-1"}
        async with httpx.AsyncClient(base_url=server.url) as http:
            assert (await http.get("/api/alerts")).status_code == 401
            assert (await http.post("/api/alerts/nope/ack", headers=desk)).status_code == 404
            alert = server.app.state.alerts.raise_("robot_lost", "R1", "robot R1 lost")
            again = server.app.state.alerts.raise_("robot_lost", "R1", "robot R1 lost")
            assert again.id == alert.id and again.count == 2  # one alert per cause
            acked = (await http.post(f"/api/alerts/{alert.id}/ack", headers=desk)).json()
            assert acked["acked_by"] == "desk" and acked["acked_at"]
            later = (await http.post(f"/api/alerts/{alert.id}/ack", headers=admin)).json()
            assert later["acked_by"] == "desk"  # the first acknowledgement stands
            assert (await http.get("/api/alerts", headers=desk)).json() == []
            everything = (await http.get("/api/alerts?include_acked=true", headers=desk)).json()
            assert [a["id"] for a in everything] == [alert.id]

            service = await http.post(
                "/api/robots/R9/service", json={"out_of_service": True}, headers=desk
            )
            assert service.status_code == 404
            out = await http.post(
                "/api/robots/R1/service", json={"out_of_service": True}, headers=desk
            )
            assert out.status_code == 200 and out.json()["out_of_service"] is True
            robots = (await http.get("/api/robots", headers=desk)).json()
            assert {r["name"]: r["out_of_service"] for r in robots}["R1"] is True

            kill = {"target": "R1", "instance_id": "R1-give_tour-1"}
            assert (await http.post("/api/nets/kill", json=kill, headers=desk)).status_code == 403
            assert (await http.post("/api/nets/kill", json=kill, headers=admin)).status_code == 404
            structure = (await http.get("/api/nets/give_tour/structure", headers=desk)).json()
            assert structure["places"] and structure["transitions"] and structure["arcs"]
            assert all(p["x"] is not None for p in structure["places"])  # PNML graphics
            assert (await http.get("/api/nets/nope/structure", headers=desk)).status_code == 404

            simulator = (await http.get("/api/building/simulator", headers=desk)).json()
            assert simulator == {"configured": False}
            press = await http.post(
                "/api/building/simulator/press", json={"button": "button_entrance"}, headers=desk
            )
            assert press.status_code == 409 and "no building simulator" in press.json()["detail"]
            alarm = await http.post(
                "/api/building/simulator/alarm",
                json={"alarm": "fire_main", "raised": True},
                headers=desk,
            )
            assert alarm.status_code == 409 and "no building simulator" in alarm.json()["detail"]
            unknown = await http.post(
                "/api/building/simulator/alarm",
                json={"alarm": "smoke", "raised": True},
                headers=desk,
            )
            assert unknown.status_code == 404
            assert "the site's alarms: fire_main" in unknown.json()["detail"]

            free = await http.post("/api/locks/corridor/release", headers=desk)
            assert free.status_code == 403  # operators: only a lock whose holder is offline
            assert (await http.post("/api/locks/corridor/release", headers=admin)).json() == {
                "area": "corridor",
                "released_from": None,
            }
            latest = (await http.get("/api/events?latest=true&limit=2", headers=desk)).json()
            ids = [e["id"] for e in latest["events"]]
            assert ids == sorted(ids) and len(ids) == 2
            # The release, then the audit row of the request that made it (docs/security.md).
            kinds = [e["kind"] for e in latest["events"]]
            assert kinds == ["area_force_released", "staff_action"], kinds


async def test_traffic_manager_alerts_are_the_consoles_alerts(tmp_path: Path) -> None:
    """One store: an alert of the Traffic Manager (an area conflict) is listed at once, once
    per cause however often it is raised (counted)."""
    settings = Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", site=SITE, building_enabled=False
    )
    async with running_server(settings) as server:
        admin = {"Authorization": f"Bearer {server.admin_token}"}
        assert server.app.state.traffic.alerts is server.app.state.alerts
        for _ in range(2):
            server.app.state.traffic.alerts.raise_(
                "area_conflict", "R2", "R2 reports being in area corridor, which R1 holds"
            )
        async with httpx.AsyncClient(base_url=server.url) as http:
            listed = (await http.get("/api/alerts", headers=admin)).json()
        assert [(a["kind"], a["subject"], a["severity"], a["count"]) for a in listed] == [
            ("area_conflict", "R2", "error", 2)
        ]
