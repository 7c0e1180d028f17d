"""Tours and points of interest: read by panels and robots, edited by admins while running."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, status

from backend.api.site import invalid
from backend.rest.deps import Admin, Anyone, Sites, not_found
from backend.site.service import SiteService
from guidebot.site.schema import PointOfInterest, Tour
from guidebot.site.validate import SiteInvalid

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["tours"])

ItemId = Annotated[str, Path(max_length=64)]


def _tour_view(service: SiteService, tour: Tour) -> dict[str, Any]:
    site = service.site
    points = [site.poi(p) for p in tour.points]
    return {
        **tour.model_dump(mode="json"),
        "stops": [
            {"poi": p.id, "name": p.name, "node": p.node, "media": p.media} for p in points if p
        ],
    }


@router.get("/tours")
async def list_tours(_: Anyone, service: Sites) -> list[dict[str, Any]]:
    return [_tour_view(service, t) for t in service.site.tours]


@router.get("/tours/{tour_id}")
async def get_tour(_: Anyone, service: Sites, tour_id: ItemId) -> dict[str, Any]:
    tour = service.site.tour(tour_id)
    if tour is None:
        raise not_found(f"tour {tour_id!r}")
    return _tour_view(service, tour)


async def _put(service: SiteService, section: str, item: dict[str, Any]) -> None:
    def change(doc: dict[str, Any]) -> None:
        items = doc[section]
        for i, old in enumerate(items):
            if old["id"] == item["id"]:
                items[i] = item
                return
        items.append(item)

    try:
        await service.edit(change)
    except SiteInvalid as exc:
        raise invalid(exc) from None


async def _delete(service: SiteService, section: str, item_id: str) -> None:
    if not any(i.id == item_id for i in getattr(service.site, section)):
        raise not_found(f"{section[:-1]} {item_id!r}")

    def change(doc: dict[str, Any]) -> None:
        doc[section] = [i for i in doc[section] if i["id"] != item_id]

    try:
        await service.edit(change)
    except SiteInvalid as exc:
        raise invalid(exc) from None


@router.put("/tours/{tour_id}")
async def put_tour(
    _: Admin, service: Sites, tour_id: ItemId, tour: Annotated[Tour, Body()]
) -> dict[str, Any]:
    """Create or replace a tour (its points must exist)."""
    data = tour.model_dump(mode="json") | {"id": tour_id}
    await _put(service, "tours", data)
    return data


@router.delete("/tours/{tour_id}", status_code=status.HTTP_204_NO_CONTENT)
async def delete_tour(_: Admin, service: Sites, tour_id: ItemId) -> None:
    await _delete(service, "tours", tour_id)


@router.get("/pois")
async def list_pois(_: Anyone, service: Sites) -> list[dict[str, Any]]:
    return [p.model_dump(mode="json") for p in service.site.pois]


@router.get("/pois/{poi_id}")
async def get_poi(_: Anyone, service: Sites, poi_id: ItemId) -> dict[str, Any]:
    poi = service.site.poi(poi_id)
    if poi is None:
        raise not_found(f"point of interest {poi_id!r}")
    return poi.model_dump(mode="json")


@router.put("/pois/{poi_id}")
async def put_poi(
    _: Admin, service: Sites, poi_id: ItemId, poi: Annotated[PointOfInterest, Body()]
) -> dict[str, Any]:
    """Create or replace a point of interest (text, media, node)."""
    data = poi.model_dump(mode="json") | {"id": poi_id}
    await _put(service, "pois", data)
    return data


@router.delete("/pois/{poi_id}", status_code=status.HTTP_204_NO_CONTENT)
async def delete_poi(_: Admin, service: Sites, poi_id: ItemId) -> None:
    """Refused (422) while a tour or button still uses the point."""
    await _delete(service, "pois", poi_id)
