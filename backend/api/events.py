"""The event log, paged by id: task changes, locks, battery alarms, faults."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query

from backend.rest.deps import Store, Watcher

__all__ = ["router"]

router = APIRouter(prefix="/api/events", tags=["events"])


@router.get("")
async def list_events(
    _: Watcher,
    db: Store,
    after_id: Annotated[int, Query(ge=0, le=2**62)] = 0,
    before_id: Annotated[int | None, Query(ge=1, le=2**62)] = None,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    kind: Annotated[str | None, Query(max_length=64)] = None,
    latest: bool = False,
    person: Annotated[str | None, Query(max_length=64)] = None,
) -> dict[str, Any]:
    """Events with id greater than ``after_id``; pass ``next_after_id`` to get the next page.
    ``latest=true``: the last ``limit`` events instead of the first (still in id order);
    ``before_id``: only events older than that id (the console pages back with
    ``latest=true&before_id=<its oldest id>``). ``person``: only what that account (or
    token name) did: its ``staff_action`` and sign-in events (docs/security.md, "Audit")."""
    events = await db.events(
        after_id=after_id, before_id=before_id, limit=limit, kind=kind, latest=latest, source=person
    )
    return {"events": events, "next_after_id": events[-1]["id"] if events else after_id}
