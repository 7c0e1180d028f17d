"""The touch screen's visitor side: texts per language from the site, pictures from the site's
folder, the link state, and requests while the link is down (queued or refused)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest

from guidebot.bus import Bus
from guidebot.site.yamlio import load_site_file
from robot_agent.clock import Clock
from robot_agent.gui import OnboardScreen, ScreenServer

pytestmark = pytest.mark.timeout(30)

SITE = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"


async def screen_for(link: list[bool], policy: str) -> tuple[OnboardScreen, ScreenServer]:
    onboard = OnboardScreen(
        Bus().endpoint("screen"),
        Clock(10.0),
        "R1",
        site=load_site_file(SITE),
        site_file=SITE,
        link_up=lambda: link[0],
        offline_requests=policy,  # type: ignore[arg-type]
    )
    await onboard.start()
    server = ScreenServer(onboard, port=0)
    await server.start()
    return onboard, server


@pytest.mark.parametrize("policy", ["queue", "refuse"])
async def test_requests_while_the_link_is_down_are_queued_or_refused_as_configured(
    policy: str,
) -> None:
    link = [True]
    onboard, server = await screen_for(link, policy)
    try:
        async with httpx.AsyncClient(base_url=server.url) as http:
            up = await http.post("/api/request", json={"kind": "tour", "tour": "ground"})
            assert up.status_code == 202 and up.json()["queued_offline"] is False
            link[0] = False
            shown = (await http.get("/api/screen")).json()["link"]
            assert shown == {"up": False, "offline_requests": policy}
            down = await http.post("/api/request", json={"kind": "tour", "tour": "ground"})
        if policy == "queue":
            assert down.status_code == 202 and down.json()["queued_offline"] is True
        else:
            assert down.status_code == 503 and "refused" in down.json()["detail"]
    finally:
        await server.stop()
        await onboard.stop()


async def test_texts_in_the_chosen_language_and_the_site_pictures() -> None:
    onboard, server = await screen_for([True], "queue")
    try:
        async with httpx.AsyncClient(base_url=server.url) as http:
            es: dict[str, Any] = (await http.get("/api/screen?lang=es")).json()
            assert es["lang"] == "es" and es["languages"] == ["en", "es", "de"]
            assert es["tours"][0]["name"] == "Visita de la planta baja"
            mosaics = next(p for p in es["pois"] if p["id"] == "mosaics")
            assert mosaics["name"] == "Mosaicos romanos"
            picture = await http.get(mosaics["media"][0]["url"])
            assert picture.status_code == 200 and picture.headers["content-type"] == "image/svg+xml"
            assert "default-src 'none'" in picture.headers["content-security-policy"]
            assert (await http.get("/media/demo_museum/missing.svg")).status_code == 404
            assert (await http.get("/media/../pyproject.toml")).status_code == 404
            assert (await http.get("/lang/es.json")).json()["yes"] == "Sí, seguimos"
            page = await http.get("/")
            assert "script-src 'self'" in page.headers["content-security-policy"]
    finally:
        await server.stop()
        await onboard.stop()


async def test_the_screen_refuses_a_step_free_visit_to_a_point_only_steps_lead_to() -> None:
    """The loom is down three steps: marked on the screen, refused step-free (422, saying
    why), sent as a step-free visit for a level point, and ``step_free`` is a yes or no."""
    onboard, server = await screen_for([True], "queue")
    sent: list[Any] = []
    onboard.ep.subscribe("task_request", sent.append)
    try:
        async with httpx.AsyncClient(base_url=server.url) as http:
            pois = (await http.get("/api/screen")).json()["pois"]
            assert {p["id"] for p in pois if p["steps_only"]} == {"loom"}
            r = await http.post(
                "/api/request", json={"kind": "go_to_poi", "poi": "loom", "step_free": True}
            )
            assert r.status_code == 422
            assert r.json()["detail"] == "only steps lead to point 'loom': no step-free visit"
            r = await http.post(
                "/api/request", json={"kind": "go_to_poi", "poi": "loom", "step_free": "yes"}
            )
            assert r.status_code == 422
            r = await http.post(
                "/api/request", json={"kind": "go_to_poi", "poi": "mosaics", "step_free": True}
            )
            assert r.status_code == 202 and r.json()["step_free"] is True
            r = await http.post("/api/request", json={"kind": "go_to_poi", "poi": "loom"})
            assert r.status_code == 202  # without steps asked for: the usual visit
        assert [m.payload["params"].get("step_free") for m in sent] == [True, None]
    finally:
        await server.stop()
        await onboard.stop()
