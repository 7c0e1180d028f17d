"""Site texts per language: pick a point's or a tour's texts in a visitor's language, falling
back field by field to the site's default language, and list the translations that are missing.

The site's own fields (``name``, ``text``...) are in the point's ``lang`` (default: the site's
``default_language``); ``translations`` give the same fields in other languages. A request in a
language the site does not offer is served in the default language.
"""

from __future__ import annotations

from typing import Any

from guidebot.site.schema import PointOfInterest, Site, Tour
from guidebot.site.validate import SiteIssue

__all__ = [
    "fallbacks",
    "missing_translations",
    "poi_texts",
    "resolve_language",
    "site_languages",
    "tour_texts",
]


def site_languages(site: Site) -> list[str]:
    """Languages offered to visitors: the default first, then the declared ones, then any
    language a translation uses."""
    seen = [site.default_language]
    extra = [*site.languages]
    for poi in site.pois:
        extra.extend(poi.translations)
    for tour in site.tours:
        extra.extend(tour.translations)
    for lang in extra:
        if lang not in seen:
            seen.append(lang)
    return seen


def resolve_language(site: Site, lang: str | None) -> str:
    """The language a request is served in: ``lang`` when offered, else the default."""
    return lang if lang and lang in site_languages(site) else site.default_language


def poi_texts(site: Site, poi: PointOfInterest, lang: str | None) -> dict[str, Any]:
    """name, description, text, media in ``lang``; ``lang`` in the answer is the language
    the spoken text is really in (the fallback's when the translation lacks it). A language
    without translations gets the point's own texts."""
    own = poi.lang or site.default_language
    want = lang or site.default_language
    extra = poi.translations.get(want) if want != own else None
    text = extra.text if extra is not None and extra.text else poi.text
    description = (
        extra.description if extra is not None and extra.description else None
    ) or poi.description
    sign = (extra.sign_video if extra is not None else None) or poi.sign_video
    return {
        "name": (extra.name if extra is not None and extra.name else None) or poi.name or poi.id,
        "description": description or text,
        "text": text,
        "media": list(extra.media if extra is not None and extra.media is not None else poi.media),
        "lang": want if extra is not None and extra.text else own,
    } | ({"sign_video": sign} if sign else {})


def fallbacks(site: Site, item: PointOfInterest | Tour, lang: str | None) -> dict[str, str]:
    """The texts of a point or a tour that ``lang`` lacks: field -> the language it is shown
    in instead (the item's own), so a page can mark them (``lang``) and tell the visitor."""
    own = (item.lang if isinstance(item, PointOfInterest) else None) or site.default_language
    want = lang or site.default_language
    if want == own:
        return {}
    extra = item.translations.get(want)
    point = isinstance(item, PointOfInterest)
    fields = ("name", "description", "text") if point else ("name", "description")
    return {
        field: own
        for field in fields
        if getattr(item, field) and (extra is None or not getattr(extra, field))
    }


def tour_texts(site: Site, tour: Tour, lang: str | None) -> dict[str, str]:
    """A tour's name and description in ``lang``, field by field falling back."""
    want = lang or site.default_language
    extra = tour.translations.get(want) if want != site.default_language else None
    return {
        "name": (extra.name if extra is not None and extra.name else None) or tour.name or tour.id,
        "description": (extra.description if extra is not None and extra.description else None)
        or tour.description,
    }


def missing_translations(site: Site) -> list[SiteIssue]:
    """Warnings (not errors): a text given in the default language but not in a declared one."""
    issues: list[SiteIssue] = []
    offered = [lang for lang in site.languages if lang != site.default_language]
    for i, poi in enumerate(site.pois):
        own = poi.lang or site.default_language
        for lang in offered:
            if lang == own:
                continue
            extra = poi.translations.get(lang)
            for field in ("name", "description", "text"):
                if getattr(poi, field) and (extra is None or not getattr(extra, field)):
                    issues.append(
                        SiteIssue(f"pois[{i}].translations.{lang}.{field}", _missing(lang))
                    )
    for i, tour in enumerate(site.tours):
        for lang in offered:
            tour_extra = tour.translations.get(lang)
            for field in ("name", "description"):
                if getattr(tour, field) and (tour_extra is None or not getattr(tour_extra, field)):
                    issues.append(
                        SiteIssue(f"tours[{i}].translations.{lang}.{field}", _missing(lang))
                    )
    undeclared = [lang for lang in site_languages(site) if lang not in site.languages]
    for lang in undeclared:
        if lang != site.default_language:
            issues.append(
                SiteIssue("languages", f"translations in {lang!r}, which is not declared")
            )
    return issues


def _missing(lang: str) -> str:
    return f"missing in {lang!r} (the default language is used)"
