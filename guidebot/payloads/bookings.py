"""Payloads of booked tours (docs/server.md, "Bookings"; docs/messages.md "Bookings")."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload

__all__ = ["NextTour", "NextTours"]


class NextTour(PayloadModel):
    """One coming public occurrence; names are looked up in the site by the reader, in its
    visitor's language (guidebot/next_tours.py)."""

    id: str = Field(max_length=32)
    kind: Literal["tour", "go_to_poi"]
    target: str = Field(max_length=64)
    """The tour's id, or the visited point's."""
    at: float
    """Unix seconds."""
    time: str
    """Its local time in the venue's time zone (``HH:MM``)."""
    lang: str = Field(max_length=16)
    """The language the tour is given in."""
    meeting_point: str = Field(max_length=64)
    """A point of interest's id."""


@register_payload("next_tours")
class NextTours(PayloadModel):
    """Today's coming public booked tours, broadcast by the server when the list changes (and
    to a robot when it connects): the visitor panel and the robots' screens show them."""

    tz: str
    tours: list[NextTour] = Field(default_factory=list, max_length=20)
