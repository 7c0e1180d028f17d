"""The next public booked tours in a visitor's language: the tour's (or point's) and the
meeting point's names from the site's translations; the page words the sentence ("Spanish tour
at 14:00, meet at the Entrance hall"). Shared by the server (``GET /api/bookings/next``) and the
robot's touch screen (the ``next_tours`` message)."""

from __future__ import annotations

from typing import Any

from guidebot.payloads.bookings import NextTour
from guidebot.site.i18n import poi_texts, tour_texts
from guidebot.site.schema import Site

__all__ = ["in_language"]


def in_language(site: Site, tours: list[NextTour], lang: str) -> list[dict[str, Any]]:
    """Each tour as shown: ``{id, at, time, lang, name, meeting_point}`` with names in ``lang``
    (a tour the site no longer has keeps its id as its name)."""
    out = []
    for item in tours:
        if item.kind == "tour":
            tour = site.tour(item.target)
            name = tour_texts(site, tour, lang)["name"] if tour else item.target
        else:
            poi = site.poi(item.target)
            name = poi_texts(site, poi, lang)["name"] if poi else item.target
        meet = site.poi(item.meeting_point)
        out.append(
            {
                "id": item.id,
                "at": item.at,
                "time": item.time,
                "lang": item.lang,
                "name": name,
                "meeting_point": poi_texts(site, meet, lang)["name"] if meet else "",
            }
        )
    return out
