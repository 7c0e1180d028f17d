"""Payload models of the site messages: a published site reaching the robots."""

from __future__ import annotations

from typing import Any

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload

__all__ = ["SiteChanged", "SiteLoaded", "SitePublished", "SiteRollout"]


@register_payload("site_changed")
class SiteChanged(PayloadModel):
    """A new site version is live (server -> robots and staff pages)."""

    version: int
    published_by: str = ""
    site: dict[str, Any] = Field(default_factory=dict)
    """The site without secrets (the robots' token digests)."""


@register_payload("site_published")
class SitePublished(PayloadModel):
    """A new site version is live (published or rolled back), said to every page: the visitor
    panels read their tours and points again at once. A few bytes, where site_changed carries
    the whole site (for the robots and the staff pages)."""

    version: int


@register_payload("site_loaded")
class SiteLoaded(PayloadModel):
    """A robot now runs with this site version (also sent on connect: 0 = none yet)."""

    robot: str = ""
    version: int


@register_payload("site_rollout")
class SiteRollout(PayloadModel):
    """How far a published version has reached the robots connected when it was published."""

    version: int
    expected: list[str] = Field(default_factory=list)
    loaded_ms: dict[str, float] = Field(default_factory=dict)
    """Robot -> milliseconds from publish to its site_loaded."""
    complete: bool = False
    ms: float | None = None
    """Publish to the last expected robot, once complete."""
