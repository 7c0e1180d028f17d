"""REST of the RoboGraph editor (/nets/, docs/nets.md): open a library net or a PNML file as the
editor's JSON, check a net with the engine's own rules, export it as PNML with its drawing.

Nothing here changes the server: the net being edited lives in the page. Reading, checking and
writing a net run in a thread (a 2 MB file takes a while to parse): the event loop keeps
serving. Staff (operators and admins) may call every route; the page lets admins edit and shows
operators the nets read-only.
Status codes: 404 for a net the library does not have, 413 for a file above ``MAX_PNML_BYTES``,
422 for a PNML file that cannot be read (every problem with its line), a net document that is
not one (FastAPI's validation errors) or a net the simulation cannot run (the engine's reasons).
"""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Body, HTTPException, Path, Request, Response, status
from pydantic import Field

from backend.api.deps import Staff, not_found
from backend.api.models import RequestBody
from guidebot.messages import known_types, payload_model
from petri_nets.library import UnknownNet
from petri_nets.model import ACTION_KINDS, CONDITION_KINDS, GUARD_TESTS, OUTCOMES
from petri_nets.netjson import (
    EditorNet,
    check_net,
    doc_to_editor,
    editor_to_doc,
    editor_to_pnml,
    pnml_to_editor,
)
from petri_nets.reachability import DEFAULT_MAX_STATES, analyse
from petri_nets.simulate import MAX_SIMULATED_FIRINGS, SimulationRefused, simulate
from petri_nets.validate import NET_OUTCOMES

__all__ = ["MAX_PNML_BYTES", "router"]

router = APIRouter(prefix="/api/net-editor", tags=["net editor"])

MAX_PNML_BYTES = 2_000_000
"""The largest PNML file the editor opens (the library's largest is under 30 kB)."""

Name = Annotated[str, Path(min_length=1, max_length=100, pattern=r"^[A-Za-z0-9_.\-]+$")]


def _fields(type_name: str) -> list[str]:
    return list(payload_model(type_name).model_fields)


@router.get("/vocabulary")
async def vocabulary(_: Staff) -> dict[str, Any]:
    """What the engine knows, offered as choices: action and condition kinds, guard tests,
    outcomes, and every registered message type with its payload fields."""
    return {
        "action_kinds": list(ACTION_KINDS),
        "condition_kinds": list(CONDITION_KINDS),
        "guard_tests": list(GUARD_TESTS),
        "final_outcomes": list(OUTCOMES),
        "net_outcomes": list(NET_OUTCOMES),
        "orders": ["sequence", "random"],
        "message_types": {t: _fields(t) for t in sorted(known_types())},
    }


@router.get("/library/{net}")
async def library_net(request: Request, _: Staff, net: Name) -> dict[str, Any]:
    """A net of the server's library as the editor's document (its PNML drawing)."""
    try:
        doc = request.app.state.rgm.library.get(net).doc
    except UnknownNet:
        raise not_found(f"net {net!r}") from None
    return doc_to_editor(doc)


@router.post("/check")
async def check(_: Staff, body: Annotated[EditorNet, Body()]) -> dict[str, Any]:
    """The problems ``guidebot petri check`` finds in the net, each naming its element
    ("net", "param:NAME", "place:ID", "transition:ID", "arc:ID")."""
    return {"problems": await asyncio.to_thread(check_net, body)}


@router.post(
    "/import",
    openapi_extra={"requestBody": {"content": {"application/xml": {"schema": {"type": "string"}}}}},
)
async def import_pnml(request: Request, _: Staff) -> dict[str, Any]:
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
async def export_pnml(_: Staff, body: Annotated[EditorNet, Body()]) -> Response:
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


@router.post("/simulate")
async def simulate_net(
    request: Request, _: Staff, body: Annotated[Simulation, Body()]
) -> dict[str, Any]:
    """Run the net at once on a virtual clock (sub-nets from the server's library) and return
    the outcome and the whole trace for the page to step through; 422 when it cannot run."""
    for message_type, replies in body.replies.items():
        if not all(isinstance(r.get("type"), str) for r in replies):
            raise HTTPException(
                status.HTTP_422_UNPROCESSABLE_CONTENT,
                f'replies to {message_type}: each reply needs a "type"',
            )
    folder = request.app.state.rgm.library.folder
    try:
        return await asyncio.to_thread(
            simulate,
            body.net,
            body.params,
            body.replies,
            folder,
            max_time=body.max_time,
            max_firings=body.max_firings,
        )
    except SimulationRefused as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None


class Analysis(RequestBody):
    net: EditorNet
    max_states: int = Field(default=DEFAULT_MAX_STATES, ge=1, le=100_000)


@router.post("/analyse")
async def analyse_net(_: Staff, body: Annotated[Analysis, Body()]) -> dict[str, Any]:
    """Boundedness, dead transitions and dead ends from the net's reachability graph, explored
    up to ``max_states`` markings (``complete`` false when it gave up there)."""
    doc, _where = editor_to_doc(body.net)
    result = await asyncio.to_thread(analyse, doc, body.max_states)
    return result.as_dict()
