"""The next public booked tours as visitors read them: names in the visitor's language (the
site's translations, docs/visitor.md), the local time; the page words the sentence."""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING, Any

from guidebot.site.i18n import poi_texts, resolve_language, tour_texts
from guidebot.site.schema import Site

if TYPE_CHECKING:
    from backend.bookings.service import BookingService

__all__ = ["next_tours"]


def next_tours(service: BookingService, site: Site, lang: str | None, limit: int) -> dict[str, Any]:
    """Today's coming public occurrences (local day), at most ``limit``: ``{"lang", "tours":
    [{"at", "time", "lang", "name", "meeting_point"}]}``."""
    lang = resolve_language(site, lang)
    now = service.clock()
    today = dt.datetime.fromtimestamp(now, service.tz).date()
    midnight = dt.datetime.combine(today + dt.timedelta(days=1), dt.time(), tzinfo=service.tz)
    tours = []
    for at, booking in service.between(now, midnight.timestamp()):
        if not booking.public:
            continue
        if booking.kind == "tour":
            tour = site.tour(booking.target)
            name = tour_texts(site, tour, lang)["name"] if tour else booking.target
        else:
            poi = site.poi(booking.target)
            name = poi_texts(site, poi, lang)["name"] if poi else booking.target
        meet = site.poi(booking.meeting_point)
        tours.append(
            {
                "id": booking.id,
                "at": at,
                "time": dt.datetime.fromtimestamp(at, service.tz).strftime("%H:%M"),
                "lang": booking.lang,
                "name": name,
                "meeting_point": poi_texts(site, meet, lang)["name"] if meet else "",
            }
        )
        if len(tours) >= limit:
            break
    return {"lang": lang, "tz": service.tz.key, "tours": tours}
