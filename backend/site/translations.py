"""The translators' view of a site document: every text per language, missing, older than its
source, or current; and the one way translations are written into the draft.

A text is named by a key: ``pois/<id>/<field>``, ``tours/<id>/<field>`` or ``emergency/words``.
Its source is the item's own text, in the item's language (a point's ``lang``, else the site's
``default_language``). A translation remembers the hash of the source it was made from
(``source_hash``, ``words_source_hash``): when the source changes, the translation is *stale*.
A translation without a hash (a site file written before hashes) is taken as current.

It works on the draft's plain document, which may have problems while it is being edited:
anything not shaped like a site is skipped, never an error.
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from guidebot.site.validate import SiteIssue

__all__ = [
    "POI_FIELDS",
    "TOUR_FIELDS",
    "Change",
    "Skipped",
    "TextEntry",
    "UnknownText",
    "WriteReport",
    "apply_translations",
    "default_language",
    "offered_languages",
    "source_hash",
    "stale_translations",
    "summary",
    "text_entries",
]

POI_FIELDS = ("name", "description", "text")
TOUR_FIELDS = ("name", "description")

State = Literal["missing", "stale", "current"]


def source_hash(text: str) -> str:
    """The first 16 hex digits of the SHA-256 of ``text`` (UTF-8), as the site stores it."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


class UnknownText(KeyError):
    """A key that names no text of the document in that language."""


@dataclass(frozen=True)
class TextEntry:
    key: str
    label: str
    """What the text is, for a person: "Point Roman mosaics (mosaics): text"."""
    source_lang: str
    source: str
    source_hash: str
    translation: str
    state: State


@dataclass(frozen=True)
class Change:
    key: str
    label: str
    before: str
    after: str
    stale: bool
    """The new translation was made from another source text than the current one."""


@dataclass(frozen=True)
class Skipped:
    key: str
    reason: str


@dataclass
class WriteReport:
    changed: list[Change] = field(default_factory=list)
    unchanged: int = 0
    skipped: list[Skipped] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _dicts(value: Any) -> Iterator[dict[str, Any]]:
    for item in value if isinstance(value, list) else []:
        if isinstance(item, dict) and isinstance(item.get("id"), str):
            yield item


def _text(value: Any) -> str:
    return value if isinstance(value, str) else ""


def default_language(doc: dict[str, Any]) -> str:
    lang = doc.get("default_language")
    return lang if isinstance(lang, str) and lang else "en"


def offered_languages(doc: dict[str, Any]) -> list[str]:
    """The default language first, the declared ones, then any a translation uses."""
    seen = [default_language(doc)]
    extra: list[Any] = list(doc.get("languages") or [])
    for section in ("pois", "tours"):
        for item in _translatable(doc.get(section)):
            extra.extend(item.get("translations") or {})
    emergency = doc.get("emergency")
    if isinstance(emergency, dict) and isinstance(emergency.get("words", {}), dict):
        extra.extend(emergency.get("words") or {})
    for lang in extra:
        if isinstance(lang, str) and lang not in seen:
            seen.append(lang)
    return seen


@dataclass
class _Slot:
    """Where one text and its translation live in the document."""

    key: str
    label: str
    source_lang: str
    source: str
    holder: dict[str, Any]
    """The item whose ``translations`` (or the emergency part whose ``words``) hold it."""
    field: str | None
    """None for the emergency words."""

    def translation(self, lang: str) -> tuple[str, str | None]:
        """The translation in ``lang`` and the hash of the source it was made from."""
        if self.field is None:
            words = self.holder.get("words") or {}
            hashes = self.holder.get("words_source_hash") or {}
            return _text(words.get(lang)), hashes.get(lang)
        extra = (self.holder.get("translations") or {}).get(lang)
        if not isinstance(extra, dict):
            return "", None
        return _text(extra.get(self.field)), (extra.get("source_hash") or {}).get(self.field)

    def write(self, lang: str, text: str, made_from: str) -> None:
        """Set (or, for an empty text, remove) the translation and its source hash."""
        if self.field is None:
            words = self.holder.setdefault("words", {})
            hashes = self.holder.setdefault("words_source_hash", {})
            if text:
                words[lang], hashes[lang] = text, source_hash(made_from)
            else:
                words.pop(lang, None)
                hashes.pop(lang, None)
            if not hashes:
                self.holder.pop("words_source_hash")
            return
        translations = self.holder.setdefault("translations", {})
        extra = translations.setdefault(lang, {})
        hashes = extra.setdefault("source_hash", {})
        if text:
            extra[self.field], hashes[self.field] = text, source_hash(made_from)
        else:
            extra.pop(self.field, None)
            hashes.pop(self.field, None)
        if not hashes:
            extra.pop("source_hash")
        if not extra:
            translations.pop(lang)
        if not translations:
            self.holder.pop("translations")


def _translatable(items: Any) -> Iterator[dict[str, Any]]:
    """Items whose ``translations`` is a mapping (or absent): a draft may hold anything."""
    for item in _dicts(items):
        if isinstance(item.get("translations", {}), dict):
            yield item


def _slots(doc: dict[str, Any]) -> Iterator[_Slot]:
    default = default_language(doc)
    for item in _translatable(doc.get("pois")):
        own = item["lang"] if isinstance(item.get("lang"), str) and item["lang"] else default
        title = f"Point {item.get('name') or item['id']} ({item['id']})"
        for name in POI_FIELDS:
            yield _Slot(
                f"pois/{item['id']}/{name}", f"{title}: {name}", own, _text(item.get(name)),
                item, name,
            )  # fmt: skip
    for item in _translatable(doc.get("tours")):
        title = f"Tour {item.get('name') or item['id']} ({item['id']})"
        for name in TOUR_FIELDS:
            yield _Slot(
                f"tours/{item['id']}/{name}", f"{title}: {name}", default, _text(item.get(name)),
                item, name,
            )  # fmt: skip
    emergency = doc.get("emergency")
    if isinstance(emergency, dict) and isinstance(emergency.get("words", {}), dict):
        words = emergency.get("words") or {}
        yield _Slot(
            "emergency/words", "Fire alarm: words", default, _text(words.get(default)),
            emergency, None,
        )  # fmt: skip


def _targets(doc: dict[str, Any], lang: str) -> Iterator[_Slot]:
    """The texts to translate into ``lang``: a source to translate, in another language."""
    for slot in _slots(doc):
        if slot.source and slot.source_lang != lang:
            yield slot


def _entry(slot: _Slot, lang: str) -> TextEntry:
    translation, made_from = slot.translation(lang)
    digest = source_hash(slot.source)
    state: State = (
        "missing"
        if not translation
        else "stale"
        if made_from is not None and made_from != digest
        else "current"
    )
    return TextEntry(
        slot.key, slot.label, slot.source_lang, slot.source, digest, translation, state
    )


def text_entries(doc: dict[str, Any], lang: str) -> list[TextEntry]:
    """Every text to translate into ``lang``, in the document's order, with its state."""
    return [_entry(slot, lang) for slot in _targets(doc, lang)]


def summary(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """Per language but the default: how many texts are missing, stale and current."""
    out = []
    for lang in offered_languages(doc)[1:]:
        counts = {"missing": 0, "stale": 0, "current": 0}
        for entry in text_entries(doc, lang):
            counts[entry.state] += 1
        out.append({"lang": lang, **counts, "total": sum(counts.values())})
    return out


def stale_translations(doc: dict[str, Any]) -> list[SiteIssue]:
    """Warnings (not errors) for ``site check``: each translation older than its source."""
    return [
        SiteIssue(f"{entry.key} in {lang!r}", "older than its source: the source text changed")
        for lang in offered_languages(doc)[1:]
        for entry in text_entries(doc, lang)
        if entry.state == "stale"
    ]


def apply_translations(
    doc: dict[str, Any], lang: str, texts: Iterable[tuple[str, str, str | None]]
) -> tuple[dict[str, Any], WriteReport]:
    """A copy of ``doc`` with ``(key, translation, source it was made from)`` written in
    ``lang`` (a None source: the current one), and what changed. Keys that name no text are
    skipped and reported; ``doc`` itself is left as it was."""
    out = copy.deepcopy(doc)
    slots = {slot.key: slot for slot in _targets(out, lang)}
    report = WriteReport()
    for key, text, made_from in texts:
        slot = slots.get(key)
        if slot is None:
            report.skipped.append(Skipped(key, _unknown(doc, key, lang)))
            continue
        before = _entry(slot, lang)
        origin = slot.source if made_from is None else made_from
        text = text.strip()
        slot.write(lang, text, origin)
        after = _entry(slot, lang)
        if (before.translation, before.state) == (after.translation, after.state):
            report.unchanged += 1
            continue
        report.changed.append(
            Change(key, slot.label, before.translation, text, after.state == "stale")
        )
    return out, report


def _unknown(doc: dict[str, Any], key: str, lang: str) -> str:
    for slot in _slots(doc):
        if slot.key == key:
            if slot.source_lang == lang:
                return f"its source is in {lang!r}: nothing to translate"
            return "its source text is empty: nothing to translate"
    return "no such text in the draft (a point or tour deleted or renamed?)"
