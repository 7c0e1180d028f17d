"""Site routes: read, replace, import and export the whole site (admin), and paths."""

from __future__ import annotations

from typing import Annotated, Any

import orjson
from fastapi import APIRouter, HTTPException, Query, Request, Response, status

from backend.rest.deps import Admin, PlanPath, Sites, Staff, Traffic
from backend.site.offloop import off_loop, release
from backend.site.tokens import secure_robot_tokens
from backend.site.yaml_import import read_site_yaml
from guidebot.site import jsonio
from guidebot.site.graph import NoPath, UnknownNode
from guidebot.site.validate import SiteInvalid
from guidebot.site.yamlio import MAX_SITE_BYTES, dump_site

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["site"])


def invalid(exc: SiteInvalid) -> HTTPException:
    return HTTPException(
        status.HTTP_422_UNPROCESSABLE_CONTENT, [issue.as_dict() for issue in exc.issues]
    )


@router.get("/site")
async def get_site(_: Admin, service: Sites) -> dict[str, Any]:
    """The whole site document with its version (robot tokens as SHA-256 digests only)."""
    return {"version": service.version, "site": service.site.model_dump(mode="json")}


@router.put(
    "/site",
    openapi_extra={
        "requestBody": {"content": {"application/json": {"schema": {"type": "object"}}}}
    },
)
async def put_site(request: Request, _: Admin, service: Sites) -> dict[str, Any]:
    """Replace the site while running; refused as a whole (422, every problem) if broken.

    The body is parsed and validated off the event loop (a 10 000-node site is megabytes),
    and the parsed document freed there too."""
    raw = await request.body()
    if len(raw) > MAX_SITE_BYTES:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, "site document too large")
    try:
        box: list[Any] = [await off_loop(jsonio.loads, raw)]
    except orjson.JSONDecodeError as exc:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT, f"not valid JSON: {exc}"
        ) from None
    if not isinstance(box[0], dict):
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT, "a site document is a JSON object"
        )
    try:
        try:
            site = await service.validate(box[0])
        finally:
            await release(box)
        await service.replace(
            await off_loop(
                secure_robot_tokens, site, development=request.app.state.settings.development
            )
        )
    except SiteInvalid as exc:
        raise invalid(exc) from None
    return {"version": service.version}


@router.get("/site/export", response_class=Response)
async def export_site(_: Admin, service: Sites) -> Response:
    """The site as a YAML file."""
    return yaml_download(dump_site(service.site))


def yaml_download(text: str) -> Response:
    """A site YAML as a file to save (the site export and the editor's draft export)."""
    return Response(
        text,
        media_type="application/yaml",
        headers={"Content-Disposition": 'attachment; filename="site.yaml"'},
    )


@router.post(
    "/site/import",
    openapi_extra={
        "requestBody": {"content": {"application/yaml": {"schema": {"type": "string"}}}}
    },
)
async def import_site(request: Request, _: Admin, service: Sites) -> dict[str, Any]:
    """Replace the site with a YAML file (request body); 422 lists every error with its line."""
    raw = await request.body()
    if len(raw) > MAX_SITE_BYTES:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, "site file too large")
    try:
        text = raw.decode("utf-8", errors="replace")
        site = await read_site_yaml(text, request.app.state.settings.site_workers)
        await service.replace(
            await off_loop(
                secure_robot_tokens, site, development=request.app.state.settings.development
            )
        )
    except SiteInvalid as exc:
        raise invalid(exc) from None
    return {"version": service.version}


@router.get("/paths")
async def get_path(
    _: PlanPath,
    traffic: Traffic,
    from_node: Annotated[str, Query(max_length=64)],
    to_node: Annotated[str, Query(max_length=64)],
) -> dict[str, Any]:
    """Shortest path between two nodes, with the doors, elevators and areas on it."""
    try:
        result = traffic.path(from_node, to_node)
    except UnknownNode as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"unknown node {exc}") from None
    except NoPath as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    return {
        "nodes": result.nodes,
        "length_m": result.length_m,
        "areas": result.areas,
        "steps": [s.as_dict() for s in result.steps],
    }


__all__ += ["Staff"]
