"""REST of bookings (docs/server.md, "Bookings"): list by period, one, its history
(``read_bookings``); create, move, cancel (``book``); the next public tours (``read``: panels
and robots' screens)."""

from __future__ import annotations

import contextlib
import datetime as dt
from collections.abc import Iterator
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Path, Query, Request, status

from backend.actions import require_action
from backend.auth import Principal
from backend.bookings.model import (
    BookingError,
    BookingRequest,
    CancelRequest,
    MoveRequest,
    local_date,
)
from backend.bookings.service import BookingService
from backend.bookings.words import next_tours
from backend.rest.deps import Anyone
from backend.state import app_state

__all__ = ["router"]

router = APIRouter(prefix="/api/bookings", tags=["bookings"])

Booker = Annotated[Principal, Depends(require_action("book"))]
Reader = Annotated[Principal, Depends(require_action("read_bookings"))]
BookingId = Annotated[str, Path(max_length=32)]
Day = Annotated[str | None, Query(pattern=r"^\d{4}-\d{2}-\d{2}$", description="local date")]

MAX_LIST_DAYS = 62
"""The longest period one listing covers."""


def _service(request: Request) -> BookingService:
    service = app_state(request.app).bookings
    if not isinstance(service, BookingService):
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, "bookings not running")
    return service


def _day(name: str, value: str) -> dt.date:
    """A query's local date, or 422 naming it (the pattern lets 2026-02-30 through)."""
    try:
        return local_date(value, name)
    except BookingError as exc:
        raise _refused(exc) from None


def _refused(exc: BookingError) -> HTTPException:
    return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc))


def _missing(booking_id: str) -> HTTPException:
    return HTTPException(status.HTTP_404_NOT_FOUND, f"booking {booking_id!r} not found")


@contextlib.contextmanager
def _answers(booking_id: str) -> Iterator[None]:
    """An unknown booking is 404; a change the booking's rules refuse is 422."""
    try:
        yield
    except KeyError:
        raise _missing(booking_id) from None
    except BookingError as exc:
        raise _refused(exc) from None


@router.get("")
async def list_bookings(
    request: Request,
    _: Reader,
    start: Day = None,
    end: Day = None,
    cancelled: bool = False,
) -> dict[str, Any]:
    """Occurrences from local date ``start`` (default today) to ``end`` inclusive (default
    ``start``), at most 62 days, in time order; ``cancelled``: cancelled bookings' too."""
    service = _service(request)
    today = dt.datetime.fromtimestamp(service.clock(), service.tz).date()
    first = _day("start", start) if start else today
    last = _day("end", end) if end else first
    if last < first:
        raise _refused(BookingError(f"end={last} is before start={first}"))
    if (last - first).days >= MAX_LIST_DAYS:
        raise _refused(BookingError(f"a listing covers at most {MAX_LIST_DAYS} days"))
    lo = dt.datetime.combine(first, dt.time(), tzinfo=service.tz).timestamp()
    hi = dt.datetime.combine(last + dt.timedelta(days=1), dt.time(), tzinfo=service.tz).timestamp()
    return {
        "tz": service.tz.key,
        "start": first.isoformat(),
        "end": last.isoformat(),
        "occurrences": [
            service.view(b, at) for at, b in service.between(lo, hi, cancelled=cancelled)
        ],
        "flags": service.flags_view(),
    }


@router.get("/next")
async def next_public(
    request: Request,
    _: Anyone,
    lang: Annotated[str | None, Query(max_length=16)] = None,
    limit: Annotated[int, Query(ge=1, le=20)] = 3,
) -> dict[str, Any]:
    """The next public booked tours of today (local), in ``lang`` (default: the site's)."""
    return next_tours(_service(request), request.app.state.sites.site, lang, limit)


@router.post("", status_code=status.HTTP_201_CREATED)
async def create(request: Request, who: Booker, body: BookingRequest) -> dict[str, Any]:
    """Book a tour (``tour``) or a single point's visit (``poi``). 422 with the reason: a time
    in the past, an unknown tour, point or language, a group under 1, more bookings at once
    than robots in service."""
    service = _service(request)
    try:
        booking = await service.create(body, by=who.name)
    except BookingError as exc:
        raise _refused(exc) from None
    return service.view(booking)


@router.get("/{booking_id}")
async def get_booking(request: Request, _: Reader, booking_id: BookingId) -> dict[str, Any]:
    service = _service(request)
    with _answers(booking_id):
        return service.view(service.get(booking_id))


@router.get("/{booking_id}/history")
async def history(request: Request, _: Reader, booking_id: BookingId) -> list[dict[str, Any]]:
    """Created, moved, cancelled (by whom), started, missed, flagged: oldest first."""
    with _answers(booking_id):
        return await _service(request).history(booking_id)


@router.post("/{booking_id}/move")
async def move(
    request: Request, who: Booker, booking_id: BookingId, body: MoveRequest
) -> dict[str, Any]:
    """A new start (a series: all its coming occurrences), meeting point, group size or note."""
    service = _service(request)
    with _answers(booking_id):
        return service.view(await service.move(booking_id, body, by=who.name))


@router.post("/{booking_id}/cancel")
async def cancel(
    request: Request, who: Booker, booking_id: BookingId, body: CancelRequest
) -> dict[str, Any]:
    """Cancel the booking, or one ``occurrence`` (a local date) of a series."""
    service = _service(request)
    with _answers(booking_id):
        return service.view(await service.cancel(booking_id, body, by=who.name))
