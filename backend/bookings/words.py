"""The next public booked tours: today's coming public occurrences (local day), as the
``next_tours`` message carries them and as ``GET /api/bookings/next`` shows them in a
visitor's language (guidebot/next_tours.py)."""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING, Any

from guidebot.next_tours import in_language
from guidebot.payloads.bookings import NextTour
from guidebot.site.i18n import resolve_language
from guidebot.site.schema import Site

if TYPE_CHECKING:
    from backend.bookings.service import BookingService

__all__ = ["MAX_NEXT", "coming", "next_tours"]

MAX_NEXT = 20
"""The most occurrences the list holds."""


def coming(service: BookingService, now: float, limit: int = MAX_NEXT) -> list[NextTour]:
    """Today's public occurrences from ``now`` to the venue's midnight, soonest first."""
    today = dt.datetime.fromtimestamp(now, service.tz).date()
    midnight = dt.datetime.combine(today + dt.timedelta(days=1), dt.time(), tzinfo=service.tz)
    found = []
    for at, booking in service.between(now, midnight.timestamp()):
        if not booking.public:
            continue
        found.append(
            NextTour(
                id=booking.id,
                kind=booking.kind,
                target=booking.target,
                at=at,
                time=dt.datetime.fromtimestamp(at, service.tz).strftime("%H:%M"),
                lang=booking.lang,
                meeting_point=booking.meeting_point,
            )
        )
        if len(found) >= limit:
            break
    return found


def next_tours(service: BookingService, site: Site, lang: str | None, limit: int) -> dict[str, Any]:
    """``{"lang", "tz", "tours": [{"id", "at", "time", "lang", "name", "meeting_point"}]}``:
    names in ``lang`` (the site's default when it is not offered)."""
    lang = resolve_language(site, lang)
    tours = coming(service, service.clock(), limit)
    return {"lang": lang, "tz": service.tz.key, "tours": in_language(site, tours, lang)}
