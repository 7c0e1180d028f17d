"""The translators' routes (rule ``administer``, as the site editor): texts of the draft per
language (missing, older than their source, current), writing translations, and gettext PO /
XLIFF files for a translation agency (docs/config.md, "Translations").

Writes go into the shared draft with its revision (409 when it moved on, as every draft save);
a file that cannot be read is refused whole (422) and the draft is left as it was.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any

from fastapi import APIRouter, Body, HTTPException, Path, Query, Request, Response, status
from pydantic import BaseModel, Field

from backend.api.site_editor import Drafts, stale
from backend.rest.deps import Admin
from backend.rest.models import RequestBody
from backend.site.draft import SiteDrafts, StaleDraft
from backend.site.offloop import off_loop
from backend.site.translation_files import (
    FORMATS,
    BadTranslationFile,
    Format,
    read_translation_file,
    write_translation_file,
)
from backend.site.translations import (
    WriteReport,
    apply_translations,
    default_language,
    offered_languages,
    summary,
    text_entries,
)
from guidebot.site.schema import LANG_PATTERN
from guidebot.site.yamlio import MAX_SITE_BYTES

__all__ = ["router"]

router = APIRouter(prefix="/api/site/draft/translations", tags=["site editor"])

LangPath = Annotated[str, Path(max_length=16, pattern=LANG_PATTERN)]


class LanguageCounts(BaseModel):
    lang: str
    missing: int
    stale: int
    """Translated from an older source text."""
    current: int
    total: int


class Overview(BaseModel):
    source_language: str
    revision: int
    languages: list[LanguageCounts]


class Text(BaseModel):
    key: str
    label: str
    source_lang: str
    source: str
    source_hash: str
    """What a translation made from this source records (``source_hash`` in the site)."""
    translation: str
    state: str
    """missing, stale (older than its source) or current."""


class LanguageTexts(BaseModel):
    lang: str
    source_language: str
    revision: int
    texts: list[Text]


class NewText(RequestBody):
    key: str = Field(min_length=1, max_length=200)
    text: str = Field(max_length=20_000)
    """The translation; empty removes it."""


class TextsWrite(RequestBody):
    revision: int = Field(ge=0)
    texts: list[NewText] = Field(min_length=1, max_length=10_000)


class ChangeOut(BaseModel):
    key: str
    label: str
    before: str
    after: str
    stale: bool


class SkippedOut(BaseModel):
    key: str
    reason: str


class WriteResult(BaseModel):
    revision: int
    changed: list[ChangeOut]
    unchanged: int
    skipped: list[SkippedOut]
    """Texts of the file not written, each with why (unknown key, not translated, fuzzy)."""


def _language(d: SiteDrafts, lang: str) -> dict[str, Any]:
    """The draft document, once ``lang`` is known to be one of its translation languages."""
    doc = d.state.data
    if lang == default_language(doc):
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"{lang!r} is the site's default language: the source, not a translation",
        )
    if lang not in offered_languages(doc):
        raise HTTPException(
            status.HTTP_404_NOT_FOUND,
            f"the draft offers no language {lang!r}: add it to the site's languages first",
        )
    return doc


async def _write(
    d: SiteDrafts, lang: str, revision: int, texts: Sequence[tuple[str, str, str | None]], by: str
) -> tuple[int, WriteReport]:
    doc = _language(d, lang)
    new, report = await off_loop(apply_translations, doc, lang, texts)
    if new == doc and revision == d.state.revision:
        return revision, report  # nothing to write: no new revision
    try:
        state = await d.save(new, revision=revision, by=by)
    except StaleDraft as exc:
        raise stale(exc) from None
    return state.revision, report


def _result(revision: int, report: WriteReport, skipped: list[SkippedOut]) -> WriteResult:
    data = report.as_dict()
    return WriteResult(
        revision=revision,
        changed=data["changed"],
        unchanged=data["unchanged"],
        skipped=[*skipped, *data["skipped"]],
    )


@router.get("")
async def overview(_: Admin, d: Drafts) -> Overview:
    """Per language but the default: how many texts are missing, stale and current."""
    doc = d.state.data
    return Overview(
        source_language=default_language(doc),
        revision=d.state.revision,
        languages=[LanguageCounts(**row) for row in summary(doc)],
    )


@router.get("/{lang}")
async def language_texts(_: Admin, d: Drafts, lang: LangPath) -> LanguageTexts:
    """Every text to translate into ``lang``, beside its source, with its state."""
    doc = _language(d, lang)
    return LanguageTexts(
        lang=lang,
        source_language=default_language(doc),
        revision=d.state.revision,
        texts=[Text(**vars(e)) for e in text_entries(doc, lang)],
    )


@router.put("/{lang}")
async def write_texts(
    who: Admin, d: Drafts, lang: LangPath, body: Annotated[TextsWrite, Body()]
) -> WriteResult:
    """Write translations made from the current source texts (each then current)."""
    texts = [(t.key, t.text, None) for t in body.texts]
    revision, report = await _write(d, lang, body.revision, texts, who.name)
    return _result(revision, report, [])


@router.get("/{lang}/export", response_class=Response)
async def export_file(
    _: Admin, d: Drafts, lang: LangPath, format: Annotated[Format, Query()] = "po"
) -> Response:
    """Every text to translate into ``lang`` as a PO or XLIFF file (stale ones fuzzy)."""
    doc = _language(d, lang)
    raw = await off_loop(
        write_translation_file,
        format,
        text_entries(doc, lang),
        source_lang=default_language(doc),
        lang=lang,
        title=str(doc.get("name") or "site"),
    )
    media, ending = FORMATS[format]
    return Response(
        raw,
        media_type=media,
        headers={"Content-Disposition": f'attachment; filename="site-{lang}{ending}"'},
    )


@router.post(
    "/{lang}/import",
    openapi_extra={
        "requestBody": {
            "content": {media: {"schema": {"type": "string"}} for media, _ in FORMATS.values()}
        }
    },
)
async def import_file(
    request: Request,
    who: Admin,
    d: Drafts,
    lang: LangPath,
    revision: Annotated[int, Query(ge=0)],
    format: Annotated[Format, Query()] = "po",
) -> WriteResult:
    """Write the translations of a PO or XLIFF file, each marked against the source text it
    was translated from; a file that cannot be read is refused whole (422)."""
    raw = await request.body()
    if len(raw) > MAX_SITE_BYTES:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, "translation file too large")
    _language(d, lang)
    try:
        units = await off_loop(read_translation_file, format, raw, lang=lang)
    except BadTranslationFile as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None
    skipped = [
        SkippedOut(
            key=u.key, reason="marked fuzzy: to be reviewed" if u.fuzzy else "not translated"
        )
        for u in units
        if u.fuzzy or not u.target.strip()
    ]
    texts = [(u.key, u.target, u.source) for u in units if not u.fuzzy and u.target.strip()]
    revision_now, report = await _write(d, lang, revision, texts, who.name)
    return _result(revision_now, report, skipped)
