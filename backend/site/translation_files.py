"""Translation files for an agency: gettext PO and XLIFF 1.2, read and written by the Translate
Toolkit (the only module that imports it).

One unit per text: its key (``pois/mosaics/text``) is the PO entry's ``msgctxt`` or the XLIFF
unit's ``id``, its source the source text as it was at export, its target the translation. A
translation older than its source is marked fuzzy (PO ``#, fuzzy``; XLIFF ``approved="no"``)
for review; fuzzy and empty units are not imported. On import the source in the file is what
the translation was made from, so a file translated from an older source imports as stale.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Literal

import defusedxml.ElementTree
from translate.storage import pypo, xliff

from backend.site.translations import TextEntry

__all__ = [
    "FORMATS",
    "BadTranslationFile",
    "FileUnit",
    "Format",
    "read_translation_file",
    "write_translation_file",
]

Format = Literal["po", "xliff"]

FORMATS: dict[str, tuple[str, str]] = {
    "po": ("text/x-gettext-translation", ".po"),
    "xliff": ("application/x-xliff+xml", ".xlf"),
}
"""Format -> its media type and file name ending."""


class BadTranslationFile(ValueError):
    """A file that is not a translation file of this site (the message says why)."""


@dataclass(frozen=True)
class FileUnit:
    key: str
    source: str
    target: str
    fuzzy: bool


def write_translation_file(
    fmt: Format, entries: Iterable[TextEntry], *, source_lang: str, lang: str, title: str
) -> bytes:
    """Every entry as one unit, with its label as a note for the translator."""
    store: Any
    if fmt == "po":
        store = pypo.pofile()
        store.updateheader(add=True, Project_Id_Version=title, Language=lang)
    else:
        store = xliff.xlifffile(sourcelanguage=source_lang, targetlanguage=lang)
    for entry in entries:
        unit = store.addsourceunit(entry.source)
        if fmt == "po":
            unit.setcontext(entry.key)
        else:
            unit.setid(entry.key)
        unit.addnote(entry.label, origin="developer")
        if entry.translation:
            unit.target = entry.translation
        unit.markfuzzy(entry.state == "stale")
    return bytes(store)


def _same_language(found: str, lang: str) -> bool:
    """``de``, ``de-DE`` and ``de_DE`` (gettext's spelling) are a file for ``de``."""
    tag = found.replace("_", "-").lower()
    return tag == lang.lower() or ("-" not in lang and tag.split("-")[0] == lang.lower())


def read_translation_file(fmt: Format, raw: bytes, *, lang: str) -> list[FileUnit]:
    """The file's units; BadTranslationFile if it cannot be read, is for another language, or
    has units without a key or with the same key twice."""
    name = "PO" if fmt == "po" else "XLIFF"
    store: Any
    try:
        if fmt == "po":
            store = pypo.pofile.parsestring(raw)
        else:
            # No DTD, no entities: a translation file from outside is untrusted XML.
            defusedxml.ElementTree.fromstring(raw, forbid_dtd=True)
            store = xliff.xlifffile.parsestring(raw)
    except Exception as exc:  # the parsers raise many kinds: all mean "not this format"
        raise BadTranslationFile(
            f"not a readable {name} file: {exc or type(exc).__name__}"
        ) from None
    found = store.gettargetlanguage()
    if found and not _same_language(found, lang):
        raise BadTranslationFile(f"this {name} file is for the language {found!r}, not {lang!r}")
    units: list[FileUnit] = []
    seen: set[str] = set()
    for n, unit in enumerate((u for u in store.units if not u.isheader()), start=1):
        key = unit.getcontext() if fmt == "po" else unit.getid().rsplit(xliff.ID_SEPARATOR, 1)[-1]
        if not key:
            where = "msgctxt" if fmt == "po" else "id"
            raise BadTranslationFile(
                f"text {n} ({str(unit.source)[:40]!r}) has no {where}: translate a file "
                "exported by the site editor"
            )
        if key in seen:
            raise BadTranslationFile(f"{key} is in the file twice")
        seen.add(key)
        units.append(FileUnit(key, str(unit.source or ""), str(unit.target or ""), unit.isfuzzy()))
    if not units:
        raise BadTranslationFile(f"the {name} file holds no texts")
    return units
