"""What the web pages need besides the domain routes: who am I, the site as a map (no secrets),
and the floor-plan images. Pages themselves are static files (backend.webpages)."""

from __future__ import annotations

from pathlib import Path as FsPath
from typing import Annotated, Any

from fastapi import APIRouter, Path, Request
from fastapi.responses import FileResponse

from backend.rest.deps import Anyone, Sites, not_found

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["web"])

PLAN_TYPES = {".svg": "image/svg+xml", ".png": "image/png", ".jpg": "image/jpeg"}
PLAN_HEADERS = {
    # A plan image is a picture: nothing in it may run or load anything.
    "Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'",
    "X-Content-Type-Options": "nosniff",
    "Cache-Control": "no-cache",
}


@router.get("/me")
async def me(who: Anyone) -> dict[str, str]:
    """The token's name and role: pages show the controls of that role."""
    return {"name": who.name, "role": who.role.value}


@router.get("/site/map")
async def site_map(request: Request, _: Anyone, service: Sites) -> dict[str, Any]:
    """The site without secrets (robot tokens): what every page draws its map from; and the
    venue's time zone (``GUIDEBOT_TIMEZONE``), the one the console shows every time in."""
    data = service.site.model_dump(mode="json")
    data["robots"] = [{k: v for k, v in robot.items() if k != "token"} for robot in data["robots"]]
    for floor in data["floors"]:
        floor["plan_url"] = f"/api/site/plans/{floor['id']}" if floor["plan_image"] else None
    timezone: str = request.app.state.settings.timezone
    return {"version": service.version, "site": data, "timezone": timezone}


def plan_file(site_file: FsPath | None, image: str) -> FsPath | None:
    """The plan image's path, relative to the site file's folder and never outside it."""
    return None if site_file is None else plan_in(site_file.resolve().parent, image)


def plan_in(folder: FsPath, image: str) -> FsPath | None:
    """The plan image's path, relative to the site folder and never outside it."""
    folder = folder.resolve()
    path = (folder / image).resolve()
    if not path.is_relative_to(folder) or path.suffix.lower() not in PLAN_TYPES:
        return None
    return path if path.is_file() else None


@router.get("/site/plans/{floor_id}", response_class=FileResponse)
async def floor_plan(
    request: Request, _: Anyone, service: Sites, floor_id: Annotated[str, Path(max_length=64)]
) -> FileResponse:
    """A floor's plan image; 404 when the floor has none (pages then draw the graph)."""
    floor = next((f for f in service.site.floors if f.id == floor_id), None)
    if floor is None or not floor.plan_image:
        raise not_found(f"plan of floor {floor_id!r}")
    path = plan_in(request.app.state.settings.files_dir(), floor.plan_image)
    if path is None:
        raise not_found(f"plan image {floor.plan_image!r}")
    return FileResponse(path, media_type=PLAN_TYPES[path.suffix.lower()], headers=PLAN_HEADERS)
