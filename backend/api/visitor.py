"""What the visitor panel and the robots' touch screens read: tours and points in a language with
their duration and the wait a request would get now, a panel's own requests, and the site's
pictures (docs/visitor.md)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Header, Path, Query, Request
from fastapi.responses import FileResponse

from backend.auth import Principal, Role
from backend.rest.deps import (
    Anyone,
    Requester,
    Sites,
    TaskReader,
    TaskRequester,
    Tasks,
    Traffic,
    not_found,
)
from guidebot.pace import PaceName
from guidebot.site.access import step_free_skips, steps_only_nodes
from guidebot.site.graph import SiteGraph
from guidebot.site.i18n import fallbacks, poi_texts, resolve_language, site_languages, tour_texts
from guidebot.site.media import MEDIA_HEADERS, MEDIA_TYPES, SERVED_TYPES, media_in, video_url
from guidebot.site.schema import Site, Tour

__all__ = ["DEVICE_HEADER", "Me", "MeRequesting", "device_requester", "media_url", "router"]

router = APIRouter(tags=["visitor"])

Lang = Annotated[str | None, Query(max_length=16)]
PaceQuery = Annotated[
    PaceName,
    Query(description="The pace the estimates are for: `slow`, a slower tour (guidebot/pace.py)"),
]

StepFreeQuery = Annotated[
    bool,
    Query(description="True: the tours' estimates are a step-free tour's (docs/visitor.md)"),
]

DEVICE_HEADER = "X-Guidebot-Device"
"""A visitor device's own id under a shared panel token (docs/visitor.md, "Devices")."""
REQUESTER_MAX = 64
"""The requester column's width (backend/db/models.py)."""


def device_requester(panel: str, device: str) -> str:
    """The requester a panel's device acts as: ``panel/device``; a long panel name is cut
    (the random device id keeps it unique)."""
    return f"{panel[: REQUESTER_MAX - len(device) - 1]}/{device}"


Device = Annotated[
    str | None,
    Header(
        alias=DEVICE_HEADER,
        min_length=16,
        max_length=40,
        pattern=r"^[A-Za-z0-9_-]+$",
        description="A panel's device: the random id the page keeps in localStorage.",
    ),
]


def _acting_as(who: Principal, device: str | None) -> str:
    """Whom a call acts for: a panel with a device id is that device (it sees and cancels
    only its own requests); any other caller is its token's name."""
    if who.role is Role.PANEL and device is not None:
        return device_requester(who.name, device)
    return who.name


async def _me(who: Requester, device: Device = None) -> str:
    return _acting_as(who, device)


async def _me_reading(who: TaskReader, device: Device = None) -> str:
    return _acting_as(who, device)


async def _me_requesting(who: TaskRequester, device: Device = None) -> str:
    return _acting_as(who, device)


Me = Annotated[str, Depends(_me)]
"""The requester a call acts as (``me: Me``): its token's name, or a panel's device."""
MeReading = Annotated[str, Depends(_me_reading)]
"""The same for reading tasks (``read_tasks``): viewers read them, and may not cancel."""
MeRequesting = Annotated[str, Depends(_me_requesting)]
"""The same for ``POST /api/tasks``, whose rule (``task_request``) lets modules in too."""


def media_url(name: str) -> str | None:
    """Where a page loads a media item from; None for what is not a picture (video)."""
    suffix = name[name.rfind(".") :].lower() if "." in name else ""
    return f"/media/{name}" if suffix in MEDIA_TYPES else None


def _pictures(names: list[str]) -> list[dict[str, Any]]:
    return [{"name": n, "url": media_url(n)} for n in names]


_skips: dict[int, tuple[SiteGraph, frozenset[str], dict[str, list[str]]]] = {}
"""id(graph) -> (graph, the nodes closed, tour id -> the stops a step-free tour skips): one look
per site version and set of closures."""


def _step_free_skips(site: Site, graph: SiteGraph, tour: Tour, closed: frozenset[str]) -> list[str]:
    found = _skips.get(id(graph))
    if found is None or found[0] is not graph or found[1] != closed:
        _skips.clear()  # the site or the closures changed
        found = _skips[id(graph)] = (graph, closed, {})
    by_tour = found[2]
    if tour.id not in by_tour:
        by_tour[tour.id] = step_free_skips(site, graph, tour, closed)
    return by_tour[tour.id]


def _poi_view(site: Site, poi_id: str, lang: str) -> dict[str, Any] | None:
    poi = site.poi(poi_id)
    if poi is None:
        return None
    texts = poi_texts(site, poi, lang)
    return {
        "id": poi.id,
        "name": texts["name"],
        "description": texts["description"],
        "media": _pictures(texts["media"]),
        "fallback": fallbacks(site, poi, lang),
        "sign_video": video_url(texts.get("sign_video")),
    }


@router.get("/api/visitor")
async def visitor_menu(
    _: Anyone,
    service: Sites,
    manager: Tasks,
    traffic: Traffic,
    lang: Lang = None,
    pace: PaceQuery = "normal",
    step_free: StepFreeQuery = False,
) -> dict[str, Any]:
    """Tours and points in ``lang`` (the site's default when not offered), each with its
    length at ``pace`` (and step-free) and what a request would be told now: available,
    busy (with the wait), or unavailable (no robot in service); the points only steps lead
    to are marked (``steps_only``)."""
    site = service.site
    estimator = manager.estimator
    chosen = resolve_language(site, lang)
    paced = {"pace": pace} if pace != "normal" else {}
    cut = steps_only_nodes(manager.graph)
    closed = frozenset(traffic.closures()) if traffic.closures is not None else frozenset()
    tours = []
    for tour in site.tours:
        stops = [v for v in (_poi_view(site, p, chosen) for p in tour.points) if v is not None]
        skips = _step_free_skips(site, manager.graph, tour, closed)
        freed = {"step_free": True} if step_free and len(skips) < len(tour.points) else {}
        told = estimator.preview(
            "tour", {"tour": tour.id, "lang": chosen} | paced | freed
        ).as_dict()
        tours.append(
            {
                "id": tour.id,
                **tour_texts(site, tour, chosen),
                "stops": stops,
                "estimate": told,
                "step_free_skips": skips,
                "fallback": fallbacks(site, tour, chosen),
            }
        )
    pois = []
    for poi in site.pois:
        view = _poi_view(site, poi.id, chosen)
        assert view is not None
        told = estimator.preview("go_to_poi", {"poi": poi.id, "lang": chosen} | paced).as_dict()
        pois.append({**view, "estimate": told, "steps_only": poi.node in cut})
    overall = estimator.service()
    if (
        overall == "available"
        and (tours or pois)
        and not any(item["estimate"]["service"] == "available" for item in (*tours, *pois))
    ):
        overall = "busy"  # the free robots are kept for booked tours (backend/bookings)
    return {
        "site": site.name,
        "languages": site_languages(site),
        "default_language": site.default_language,
        "lang": chosen,
        "pace": pace,
        "step_free": step_free,
        "service": overall,
        "tours": tours,
        "pois": pois,
    }


@router.get("/api/visitor/requests")
async def my_requests(me: Me, manager: Tasks) -> list[dict[str, Any]]:
    """The caller's own tasks that are not finished (a panel, or a panel's device, never
    sees another's)."""
    mine = [
        t for t in manager.tasks.values() if t.requester == me and not t.final and not t.internal
    ]
    return [manager.status(t) for t in sorted(mine, key=lambda t: t.seq)]


@router.get("/media/{name:path}", response_class=FileResponse, include_in_schema=True)
async def media(request: Request, name: Annotated[str, Path(max_length=300)]) -> FileResponse:
    """A picture or a sign-language video of the site (public, like the museum's own
    leaflets); 404 when missing, and the pages show a placeholder."""
    path = media_in(request.app.state.settings.files_dir(), name)
    if path is None:
        raise not_found(f"media {name!r}")
    return FileResponse(path, media_type=SERVED_TYPES[path.suffix.lower()], headers=MEDIA_HEADERS)
