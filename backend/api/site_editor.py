"""The site editor's routes (admin): the shared draft, publish, history, diff, roll back,
YAML import/export of the draft, plan and media uploads, robot token regeneration.

Status codes: 409 for a stale draft (someone saved or published in between: the body says who
and when), 422 for an invalid site (every problem with its place, and line for YAML), 413 for
an upload over its limit, 415 for an upload of the wrong type.
"""

from __future__ import annotations

import hashlib
import secrets
from pathlib import Path as FsPath
from typing import Annotated, Any

from fastapi import APIRouter, Body, Depends, HTTPException, Path, Query, Request, Response, status
from fastapi.responses import FileResponse
from pydantic import Field

from backend.api.site import invalid, yaml_download
from backend.auth import token_digest
from backend.db.store import DbStore
from backend.rest.deps import Admin, Sites, Store, app_service, error_response, not_found
from backend.rest.models import RequestBody
from backend.site.diff import site_diff
from backend.site.draft import SiteDrafts, StaleDraft, check_document
from backend.site.offloop import off_loop
from backend.site.rollout import RolloutTracker
from backend.site.service import SiteService
from backend.site.tokens import hash_robot_tokens, secure_robot_tokens
from backend.site.yaml_import import read_site_yaml
from guidebot.payloads.site import SiteRollout
from guidebot.site.bulk import dump_site_doc
from guidebot.site.schema import Site
from guidebot.site.validate import SiteInvalid, validate_site
from guidebot.site.yamlio import MAX_SITE_BYTES, dump_site

__all__ = ["MAX_MEDIA_BYTES", "MAX_PLAN_BYTES", "router"]

router = APIRouter(prefix="/api/site", tags=["site editor"])

MAX_PLAN_BYTES = 4_000_000
MAX_MEDIA_BYTES = 5_000_000
PLAN_TYPES = {"image/png": ".png", "image/jpeg": ".jpg", "image/svg+xml": ".svg"}
MEDIA_TYPES = {**PLAN_TYPES, "audio/mpeg": ".mp3", "video/mp4": ".mp4"}
UPLOAD_HEADERS = {
    "Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'",
    "X-Content-Type-Options": "nosniff",
}


def drafts(request: Request) -> SiteDrafts:
    return app_service(request, "site_drafts", SiteDrafts)


def rollout(request: Request) -> RolloutTracker:
    return app_service(request, "site_rollout", RolloutTracker)


Drafts = Annotated[SiteDrafts, Depends(drafts)]
Rollout = Annotated[RolloutTracker, Depends(rollout)]


def stale(exc: StaleDraft) -> HTTPException:
    s = exc.current
    return HTTPException(
        status.HTTP_409_CONFLICT,
        {
            "msg": str(exc),
            "revision": s.revision,
            "base_version": s.base_version,
            "updated_by": s.updated_by,
            "updated_at": s.updated_at,
        },
    )


def _issues(data: Any) -> list[dict[str, Any]]:
    return [i.as_dict() for i in check_document(data)]


def _state(d: SiteDrafts, live: SiteService) -> dict[str, Any]:
    return {
        **d.state.as_dict(),
        "live_version": live.version,
        "issues": _issues(d.state.data),
    }


MAX_VERSION = 2**63 - 1
"""The largest version number a database integer holds: larger ones are refused (422)."""


class Revision(RequestBody):
    revision: int = Field(ge=0)
    """The draft's revision this change is made on (409 when it moved on)."""


class DraftSave(Revision):
    draft: dict[str, Any]


class Publish(Revision):
    note: str = Field(default="", max_length=500)


class Rollback(RequestBody):
    version: int = Field(ge=1, le=MAX_VERSION)


@router.get("/draft")
async def get_draft(_: Admin, d: Drafts, live: Sites) -> dict[str, Any]:
    """The shared draft, its revision (send it back with every save), the live version and
    the draft's problems (the checks of ``guidebot site check``)."""
    return _state(d, live)


@router.put("/draft")
async def put_draft(
    who: Admin,
    d: Drafts,
    body: Annotated[DraftSave, Body()],
) -> dict[str, Any]:
    """Save the draft (it may have problems: they come back in ``issues``); 409 if stale."""
    try:
        state = await d.save(body.draft, revision=body.revision, by=who.name)
    except StaleDraft as exc:
        raise stale(exc) from None
    return {"revision": state.revision, "issues": _issues(state.data)}


@router.post("/draft/reset")
async def reset_draft(who: Admin, d: Drafts, live: Sites) -> dict[str, Any]:
    """Throw the draft away and start again from the live site."""
    await d.reset(by=who.name)
    return _state(d, live)


@router.get("/draft/export", response_class=Response)
async def export_draft(_: Admin, d: Drafts) -> Response:
    """The draft as a YAML file (stable: same content, same order); 422 if it has problems."""
    try:
        text = dump_site(validate_site(d.state.data))
    except SiteInvalid as exc:
        raise invalid(exc) from None
    return yaml_download(text)


@router.post(
    "/draft/import",
    openapi_extra={
        "requestBody": {"content": {"application/yaml": {"schema": {"type": "string"}}}}
    },
)
async def import_draft(
    request: Request,
    who: Admin,
    d: Drafts,
    live: Sites,
    revision: Annotated[int, Query(ge=0)],
) -> dict[str, Any]:
    """Replace the draft with a YAML file; a broken file is refused (422, every problem with
    its line) and the draft is left as it was."""
    raw = await request.body()
    if len(raw) > MAX_SITE_BYTES:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, "site file too large")
    try:
        text = raw.decode("utf-8", errors="replace")
        site = await read_site_yaml(text, request.app.state.settings.site_workers)
        site = await off_loop(hash_robot_tokens, site)
        await d.save(await off_loop(dump_site_doc, site), revision=revision, by=who.name)
    except SiteInvalid as exc:
        raise invalid(exc) from None
    except StaleDraft as exc:
        raise stale(exc) from None
    return _state(d, live)


@router.post("/publish")
async def publish(
    request: Request,
    who: Admin,
    d: Drafts,
    body: Annotated[Publish, Body()],
) -> dict[str, Any]:
    """Make the draft live without a restart: Task Manager, Traffic Manager,
    BuildingInterface and every connected robot get it (``site_changed``)."""

    def secure(site: Site) -> Site:
        return secure_robot_tokens(site, development=request.app.state.settings.development)

    try:
        version = await d.publish(
            revision=body.revision, by=who.name, secure=secure, note=body.note
        )
    except SiteInvalid as exc:
        raise invalid(exc) from None
    except StaleDraft as exc:
        raise stale(exc) from None
    return {"version": version, "revision": d.state.revision}


@router.get("/versions")
async def versions(_: Admin, db: Store) -> list[dict[str, Any]]:
    """Every published version, newest first: who published it, when, and a note."""
    return await db.site_versions()


async def _version_data(db: DbStore, version: int) -> dict[str, Any]:
    data = await db.site_version(version)
    if data is None:
        raise not_found(f"site version {version}")
    return data


@router.get("/versions/{version}")
async def version_document(
    _: Admin, db: Store, version: Annotated[int, Path(ge=1, le=MAX_VERSION)]
) -> dict[str, Any]:
    return {"version": version, "site": await _version_data(db, version)}


@router.get("/diff")
async def diff(
    _: Admin,
    d: Drafts,
    db: Store,
    from_version: Annotated[int, Query(alias="from", ge=1, le=MAX_VERSION)],
    to: Annotated[str, Query(max_length=16, pattern=r"^(\d+|draft)$")] = "draft",
) -> list[dict[str, Any]]:
    """What changed from a version to another version (or to the draft), element by element."""
    old = await _version_data(db, from_version)
    new = d.state.data if to == "draft" else await _version_data(db, int(to))
    return site_diff(old, new)


@router.post("/rollback")
async def rollback(
    request: Request,
    who: Admin,
    d: Drafts,
    db: Store,
    body: Annotated[Rollback, Body()],
) -> dict[str, Any]:
    """Publish a kept version again (as a new version); the draft becomes that site."""
    version = body.version
    data = await _version_data(db, version)

    def secure(site: Site) -> Site:
        return secure_robot_tokens(site, development=request.app.state.settings.development)

    try:
        new = await d.rollback(data, version=version, by=who.name, secure=secure)
    except SiteInvalid as exc:
        raise invalid(exc) from None
    return {"version": new, "revision": d.state.revision}


@router.get("/rollout")
async def rollout_status(_: Admin, r: Rollout) -> SiteRollout:
    """How far the last published version reached the robots connected at publish time."""
    return r.status()


@router.post("/draft/robots/{name}/token")
async def regenerate_token(
    who: Admin,
    d: Drafts,
    name: Annotated[str, Path(max_length=64)],
    body: Annotated[Revision, Body()],
) -> dict[str, Any]:
    """A new token for a robot: returned once, only its digest is kept (in the draft; live on
    publish)."""
    data = d.state.data
    robots = data.get("robots") if isinstance(data, dict) else None
    robot = next(
        (r for r in robots or [] if isinstance(r, dict) and r.get("name") == name),
        None,
    )
    if robot is None:
        raise not_found(f"robot {name!r} in the draft")
    token = secrets.token_urlsafe(24)
    robot["token"] = token_digest(token)
    try:
        state = await d.save(data, revision=body.revision, by=who.name)
    except StaleDraft as exc:
        raise stale(exc) from None
    return {"robot": name, "token": token, "revision": state.revision}


def upload_dir(request: Request) -> FsPath:
    """Uploads live in the site folder's uploads/ (plan and media paths are relative to it)."""
    folder: FsPath = request.app.state.settings.files_dir()
    return folder / "uploads"


async def _store_upload(request: Request, types: dict[str, str], limit: int) -> str:
    kind = (request.headers.get("content-type") or "").split(";")[0].strip().lower()
    if kind not in types:
        raise HTTPException(
            status.HTTP_415_UNSUPPORTED_MEDIA_TYPE,
            f"{kind or 'no content type'}: expected one of {', '.join(sorted(types))}",
        )
    raw = await request.body()
    if len(raw) > limit:
        raise HTTPException(
            status.HTTP_413_CONTENT_TOO_LARGE, f"file too large: the limit is {limit} bytes"
        )
    if not raw:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, "empty file")
    folder = upload_dir(request)
    folder.mkdir(parents=True, exist_ok=True)
    name = hashlib.sha256(raw).hexdigest()[:32] + types[kind]
    (folder / name).write_bytes(raw)
    return f"uploads/{name}"


UPLOAD_ERRORS: dict[int | str, dict[str, Any]] = {
    415: error_response("the Content-Type is missing or not one of the accepted file types"),
    409: error_response("this server has no site folder for uploads (started without --site)"),
}


@router.post("/uploads/plan", responses=UPLOAD_ERRORS)
async def upload_plan(request: Request, _: Admin) -> dict[str, str]:
    """Store a floor plan (PNG, JPEG or SVG, at most MAX_PLAN_BYTES); returns the path to put
    in the floor's ``plan_image``."""
    return {"path": await _store_upload(request, PLAN_TYPES, MAX_PLAN_BYTES)}


@router.post("/uploads/media", responses=UPLOAD_ERRORS)
async def upload_media(request: Request, _: Admin) -> dict[str, str]:
    """Store a point of interest's media file; returns the path to add to its ``media``."""
    return {"path": await _store_upload(request, MEDIA_TYPES, MAX_MEDIA_BYTES)}


@router.get("/uploads/{name}", response_class=FileResponse)
async def uploaded(
    request: Request, _: Admin, name: Annotated[str, Path(pattern=r"^[0-9a-f]{32}\.[a-z0-9]+$")]
) -> FileResponse:
    """An uploaded file, for the editor to show before it is published."""
    path = upload_dir(request) / name
    kinds = {ext: kind for kind, ext in MEDIA_TYPES.items()}
    if not path.is_file() or path.suffix not in kinds:
        raise not_found(f"upload {name}")
    return FileResponse(path, media_type=kinds[path.suffix], headers=UPLOAD_HEADERS)
