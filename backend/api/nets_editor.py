"""REST of the RoboGraph editor (/nets/, docs/nets.md): open a library net or a PNML file as the
editor's JSON, check a net with the engine's own rules, export it as PNML with its drawing;
publish it into the library (every version kept, compared, restorable) for the fleet to run.

Only publish and restore change the server (rule ``edit_nets``): the net being edited lives in
the page. Reading, checking and writing a net run in a thread (a 2 MB file takes a while to
parse): the event loop keeps serving. Readers (rule ``read_nets``: operators, authors, viewers)
may call every other route;
the page lets those who may publish edit and shows the others the nets read-only.
Status codes: 404 for a net (or version) the library does not have, 413 for a file above
``MAX_PNML_BYTES``, 422 for a PNML file that cannot be read (every problem with its line), a
net document that is not one (FastAPI's validation errors), a net the simulation cannot run or
the library refuses to publish (the engine's reasons).
"""

from __future__ import annotations

import asyncio
from typing import Annotated, Any, Literal

from fastapi import (
    APIRouter,
    Body,
    Depends,
    HTTPException,
    Path,
    Query,
    Request,
    Response,
    status,
)
from pydantic import Field

from backend.actions import allowed_roles
from backend.auth import Principal
from backend.console.feed import ConsoleFeed
from backend.net_library.service import NetPublisher, NetRefused
from backend.rest.deps import NetReader, app_service, not_found, require_action
from backend.rest.models import RequestBody
from guidebot.messages import known_types, payload_model
from guidebot.payloads.petri import PetriNetDebug
from petri_nets.library import NetLibrary, UnknownNet
from petri_nets.model import ACTION_KINDS, CONDITION_KINDS, GUARD_TESTS, OUTCOMES
from petri_nets.netdiff import net_diff
from petri_nets.netjson import (
    EditorNet,
    check_net,
    doc_to_editor,
    editor_to_doc,
    editor_to_pnml,
    pnml_to_editor,
)
from petri_nets.reachability import DEFAULT_MAX_STATES, analyse
from petri_nets.simulate import (
    MAX_SIMULATED_FIRINGS,
    SimulationRefused,
    simulate,
    simulate_stepwise,
)
from petri_nets.validate import NET_OUTCOMES

__all__ = ["MAX_PNML_BYTES", "router"]

router = APIRouter(prefix="/api/net-editor", tags=["net editor"])

MAX_PNML_BYTES = 2_000_000
"""The largest PNML file the editor opens (the library's largest is under 30 kB)."""

MAX_VERSION = 2**31 - 1
"""A version number the database's integer column can hold (larger: 422, not a 500)."""

Name = Annotated[str, Path(min_length=1, max_length=100, pattern=r"^[A-Za-z0-9_.\-]+$")]
NetAuthor = Annotated[Principal, Depends(require_action("edit_nets"))]
"""Who may publish nets to the fleet and restore old versions (docs/server.md)."""


def publisher(request: Request) -> NetPublisher:
    return app_service(request, "net_library", NetPublisher)


Publisher = Annotated[NetPublisher, Depends(publisher)]


def _fields(type_name: str) -> list[str]:
    return list(payload_model(type_name).model_fields)


@router.get("/vocabulary")
async def vocabulary(who: NetReader) -> dict[str, Any]:
    """What the engine knows, offered as choices: action and condition kinds, guard tests,
    outcomes, and every registered message type with its payload fields; and whether the
    caller may publish (the page shows the others the nets read only)."""
    return {
        "may_publish": who.role in allowed_roles("edit_nets"),
        "action_kinds": list(ACTION_KINDS),
        "condition_kinds": list(CONDITION_KINDS),
        "guard_tests": list(GUARD_TESTS),
        "final_outcomes": list(OUTCOMES),
        "net_outcomes": list(NET_OUTCOMES),
        "orders": ["sequence", "random"],
        "message_types": {t: _fields(t) for t in sorted(known_types())},
    }


@router.get("/library/{net}")
async def library_net(request: Request, _: NetReader, net: Name) -> dict[str, Any]:
    """A net of the server's library as the editor's document (its PNML drawing)."""
    try:
        doc = request.app.state.rgm.library.get(net).doc
    except UnknownNet:
        raise not_found(f"net {net!r}") from None
    return doc_to_editor(doc)


@router.post("/check")
async def check(_: NetReader, body: Annotated[EditorNet, Body()]) -> dict[str, Any]:
    """The problems ``guidebot petri check`` finds in the net, each naming its element
    ("net", "param:NAME", "place:ID", "transition:ID", "arc:ID")."""
    return {"problems": await asyncio.to_thread(check_net, body)}


@router.post(
    "/import",
    openapi_extra={"requestBody": {"content": {"application/xml": {"schema": {"type": "string"}}}}},
)
async def import_pnml(request: Request, _: NetReader) -> dict[str, Any]:
    """A PNML file (the request body) as the editor's document; one the reader cannot make a
    net of is refused (422, every problem with its line)."""
    raw = await request.body()
    if len(raw) > MAX_PNML_BYTES:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, "PNML file too large")
    if not raw.strip():
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, ["the PNML file is empty"])
    net, problems = await asyncio.to_thread(pnml_to_editor, raw, "upload.pnml")
    if net is None:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, problems)
    return {"net": net, "problems": problems}


@router.post("/export")
async def export_pnml(_: NetReader, body: Annotated[EditorNet, Body()]) -> Response:
    """The net as a PNML file with its drawing, for download (``guidebot petri run`` runs it)."""
    data = await asyncio.to_thread(editor_to_pnml, body)
    return Response(
        data,
        media_type="application/xml",
        headers={"Content-Disposition": f'attachment; filename="{body.id}.pnml"'},
    )


class Simulation(RequestBody):
    """A net to run against the scripted environment of ``guidebot petri run``."""

    net: EditorNet
    params: dict[str, Any] = Field(default_factory=dict)
    replies: dict[str, list[dict[str, Any]]] = Field(default_factory=dict)
    """Per message type, the replies instead of the default ones (``[]``: never answered)."""
    max_time: float = Field(default=3600.0, gt=0, le=86_400)
    max_firings: int = Field(default=MAX_SIMULATED_FIRINGS, ge=1, le=MAX_SIMULATED_FIRINGS)
    chosen: list[dict[str, Any]] | None = Field(default=None, max_length=10_000)
    """Replies chosen one at a time (``{"type", "payload"}``, or ``{"wait": true}``: to the
    next timer) instead of the scripted ones: the answer says what the net waits for next."""


@router.post("/simulate")
async def simulate_net(
    request: Request, _: NetReader, body: Annotated[Simulation, Body()]
) -> dict[str, Any]:
    """Run the net at once on a virtual clock (sub-nets from the server's library) and return
    the outcome and the whole trace for the page to step through; 422 when it cannot run."""
    for message_type, replies in body.replies.items():
        if not all(isinstance(r.get("type"), str) for r in replies):
            raise HTTPException(
                status.HTTP_422_UNPROCESSABLE_CONTENT,
                f'replies to {message_type}: each reply needs a "type"',
            )
    library: NetLibrary = request.app.state.rgm.library
    if body.chosen is not None:
        for choice in body.chosen:
            if choice.get("wait") is not True and not isinstance(choice.get("type"), str):
                raise HTTPException(
                    status.HTTP_422_UNPROCESSABLE_CONTENT,
                    'each chosen reply needs a "type" (or "wait": true)',
                )
        try:
            return await asyncio.to_thread(
                simulate_stepwise,
                body.net,
                body.params,
                body.chosen,
                library.folder,
                max_firings=body.max_firings,
                published=library.installed,
            )
        except SimulationRefused as exc:
            raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None
    try:
        return await asyncio.to_thread(
            simulate,
            body.net,
            body.params,
            body.replies,
            library.folder,
            max_time=body.max_time,
            max_firings=body.max_firings,
            published=library.installed,
        )
    except SimulationRefused as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None


class Analysis(RequestBody):
    net: EditorNet
    max_states: int = Field(default=DEFAULT_MAX_STATES, ge=1, le=100_000)


@router.post("/analyse")
async def analyse_net(_: NetReader, body: Annotated[Analysis, Body()]) -> dict[str, Any]:
    """Boundedness, dead transitions and dead ends from the net's reachability graph, explored
    up to ``max_states`` markings (``complete`` false when it gave up there)."""
    doc, _where = editor_to_doc(body.net)
    result = await asyncio.to_thread(analyse, doc, body.max_states)
    return result.as_dict()


class Publication(RequestBody):
    """A net to publish as the next version of the library's net of its id."""

    net: EditorNet
    note: str = Field(default="", max_length=2000)
    """Why (shown in the history)."""


def _published(saved: Any) -> dict[str, Any]:
    return {"net": saved.net, **saved.summary()}


@router.post("/publish")
async def publish(
    who: NetAuthor, nets: Publisher, body: Annotated[Publication, Body()]
) -> dict[str, Any]:
    """Check the net by the engine's rules, then against the library it joins (the sub-nets it
    runs, the nets that run it); store it as its net's next version and send it to the fleet:
    the server and every robot start new instances on it, running ones finish on theirs. 422
    with every problem when refused (nothing stored)."""
    problems = await asyncio.to_thread(check_net, body.net)
    if problems:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            [f"{p['element']}: {p['message']}" for p in problems],
        )
    pnml = (await asyncio.to_thread(editor_to_pnml, body.net)).decode()
    try:
        saved = await nets.publish(body.net.id, pnml, by=who.name, note=body.note)
    except NetRefused as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, exc.problems) from None
    return _published(saved)


async def _pnml_of(request: Request, nets: NetPublisher, net: str, version: int) -> str:
    """A kept version's PNML; version 0 is the file the library's folder ships (404 if none)."""
    if version == 0:
        library: NetLibrary = request.app.state.rgm.library
        path = library.folder / f"{net}.pnml"
        if not path.is_file():
            raise not_found(f"net {net!r} version 0")
        return await asyncio.to_thread(path.read_text)
    kept = await nets.store.version(net, version)
    if kept is None:
        raise not_found(f"net {net!r} version {version}")
    return kept.pnml


async def _editor_doc(pnml: str, net: str) -> dict[str, Any]:
    doc, problems = await asyncio.to_thread(pnml_to_editor, pnml, f"{net}.pnml")
    if doc is None:  # a stored file always reads; a folder file edited by hand may not
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, problems)
    return doc


@router.get("/versions/{net}")
async def versions(request: Request, _: NetReader, nets: Publisher, net: Name) -> dict[str, Any]:
    """Every published version of the net, newest first, with who, when and why; ``live`` is
    the version robots start (0: the library folder's own file, never replaced)."""
    kept = await nets.store.versions(net)
    shipped = (request.app.state.rgm.library.folder / f"{net}.pnml").is_file()
    if not kept and not shipped:
        raise not_found(f"net {net!r}")
    return {
        "net": net,
        "live": kept[0].version if kept else 0,
        "shipped": shipped,
        "versions": [v.summary() for v in kept],
        "library_version": nets.version,
    }


@router.get("/versions/{net}/{version}")
async def version(
    request: Request,
    _: NetReader,
    nets: Publisher,
    net: Name,
    version: Annotated[int, Path(ge=0, le=MAX_VERSION)],
) -> dict[str, Any]:
    """One version of the net as the editor's document (0: the library folder's file)."""
    return await _editor_doc(await _pnml_of(request, nets, net, version), net)


@router.get("/diff/{net}")
async def diff(
    request: Request,
    _: NetReader,
    nets: Publisher,
    net: Name,
    old: Annotated[int, Query(ge=0, le=MAX_VERSION)],
    new: Annotated[int, Query(ge=0, le=MAX_VERSION)],
) -> dict[str, Any]:
    """What changed from version ``old`` to ``new``, one readable line per element."""
    before = await _editor_doc(await _pnml_of(request, nets, net, old), net)
    after = await _editor_doc(await _pnml_of(request, nets, net, new), net)
    return {"net": net, "old": old, "new": new, "changes": net_diff(before, after)}


class Restore(RequestBody):
    note: str = Field(default="", max_length=2000)


@router.post("/restore/{net}/{version}")
async def restore(
    request: Request,
    who: NetAuthor,
    nets: Publisher,
    net: Name,
    version: Annotated[int, Path(ge=0, le=MAX_VERSION)],
    body: Annotated[Restore, Body()],
) -> dict[str, Any]:
    """Publish an old version again, as the net's next version (the history only grows)."""
    pnml = await _pnml_of(request, nets, net, version)
    note = body.note or f"restored version {version}"
    try:
        saved = await nets.publish(net, pnml, by=who.name, note=note)
    except NetRefused as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, exc.problems) from None
    return _published(saved)


@router.get("/rollout")
async def rollout(_: NetReader, nets: Publisher) -> dict[str, Any]:
    """The library's version and the version each robot said it starts nets from."""
    return nets.status()


class Debug(RequestBody):
    """A debugger's command for one running instance (docs/nets.md, "Attach")."""

    target: str = Field(min_length=1, max_length=64)
    """A robot name, or "rgm" for the server's own nets."""
    instance_id: str = Field(min_length=1, max_length=200)
    command: Literal["break", "step", "resume"]
    breakpoints: list[str] = Field(default_factory=list, max_length=1000)
    lease_s: float = Field(default=30.0, gt=0, le=3600)


@router.post("/debug")
async def debug(request: Request, who: NetAuthor, body: Annotated[Debug, Body()]) -> dict[str, Any]:
    """Set an instance's breakpoints (for ``lease_s`` seconds: the page renews them while it
    is attached), step past the transition it is paused before, or resume it; on a robot
    (``petri_net_debug``) or on the server. 404 for an instance not running there."""
    feed: ConsoleFeed = app_service(request, "console", ConsoleFeed)
    known = {n["instance_id"] for n in feed.running_nets(body.target)}
    if body.instance_id not in known:
        raise not_found(f"net instance {body.instance_id!r} on {body.target!r}")
    command = PetriNetDebug(
        instance_id=body.instance_id,
        command=body.command,
        breakpoints=body.breakpoints,
        lease_s=body.lease_s,
    )
    if body.target == "rgm":
        request.app.state.rgm.debug(command)
    else:
        feed.endpoint.publish(command, destination=body.target)
    return {"target": body.target, "instance_id": body.instance_id, "by": who.name}
