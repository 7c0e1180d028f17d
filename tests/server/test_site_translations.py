"""The translators' workflow on the server: texts per language (missing, older than their
source, current), writing them, and PO / XLIFF round trips through a translation agency."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml
from click.testing import CliRunner
from translate.storage import pypo, xliff

from backend.site.cli import site as site_cli
from backend.site.translations import apply_translations, source_hash, summary, text_entries
from backend.testing import RunningServer
from guidebot.site.validate import validate_site
from tests.server.conftest import OPERATOR_TOKEN

pytestmark = pytest.mark.timeout(60)

Http = Callable[[str | None], httpx.AsyncClient]
BASE = "/api/site/draft/translations"
DEMO = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"


async def _draft(admin: httpx.AsyncClient) -> dict[str, Any]:
    r = await admin.get("/api/site/draft")
    assert r.status_code == 200, r.text
    return r.json()  # type: ignore[no-any-return]


async def _texts(admin: httpx.AsyncClient, lang: str) -> dict[str, dict[str, Any]]:
    r = await admin.get(f"{BASE}/{lang}")
    assert r.status_code == 200, r.text
    return {t["key"]: t for t in r.json()["texts"]}


async def _edit_source(admin: httpx.AsyncClient, poi: str, field: str, text: str) -> int:
    state = await _draft(admin)
    doc = state["draft"]
    next(p for p in doc["pois"] if p["id"] == poi)[field] = text
    r = await admin.put("/api/site/draft", json={"draft": doc, "revision": state["revision"]})
    assert r.status_code == 200, r.text
    return r.json()["revision"]  # type: ignore[no-any-return]


async def _write(
    admin: httpx.AsyncClient, lang: str, revision: int, key: str, text: str
) -> httpx.Response:
    body = {"revision": revision, "texts": [{"key": key, "text": text}]}
    return await admin.put(f"{BASE}/{lang}", json=body)


async def _import(
    admin: httpx.AsyncClient, lang: str, raw: bytes, fmt: str = "po", revision: int | None = None
) -> httpx.Response:
    if revision is None:
        revision = (await _draft(admin))["revision"]
    return await admin.post(
        f"{BASE}/{lang}/import", params={"revision": revision, "format": fmt}, content=raw
    )


async def test_counts_per_language_and_a_changed_source_makes_its_translation_stale(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    overview = (await admin.get(BASE)).json()
    assert overview["source_language"] == "en"
    langs = {row["lang"]: row for row in overview["languages"]}
    assert set(langs) == {"es", "de"}
    # The demo's translations have no source hashes (written before them): taken as current.
    assert langs["es"]["stale"] == 0 and langs["es"]["missing"] == 0
    assert langs["es"]["current"] == langs["es"]["total"] > 0
    texts = await _texts(admin, "es")
    mosaics = texts["pois/mosaics/text"]
    assert mosaics["source"] == "These mosaics come from a Roman villa."
    assert mosaics["translation"] == "Estos mosaicos proceden de una villa romana."
    assert texts["emergency/words"]["translation"].startswith("Alarma de incendio")
    # A translator confirms it: the hash of its source is recorded.
    revision = (await _draft(admin))["revision"]
    r = await _write(admin, "es", revision, "pois/mosaics/text", mosaics["translation"])
    assert r.status_code == 200, r.text
    assert r.json()["changed"] == [] and r.json()["unchanged"] == 1
    doc = (await _draft(admin))["draft"]
    es = next(p for p in doc["pois"] if p["id"] == "mosaics")["translations"]["es"]
    assert es["source_hash"] == {"text": source_hash(mosaics["source"])}
    # The source changes: the translation is now older than its source, in every language
    # that recorded a hash; the others (no hash) stay current.
    await _edit_source(admin, "mosaics", "text", "These mosaics come from a villa near Rome.")
    texts = await _texts(admin, "es")
    assert texts["pois/mosaics/text"]["state"] == "stale"
    assert texts["pois/mosaics/name"]["state"] == "current"
    es_row = next(r for r in (await admin.get(BASE)).json()["languages"] if r["lang"] == "es")
    assert es_row["stale"] == 1
    # A new translation of the new source makes it current again.
    revision = (await _draft(admin))["revision"]
    new = "Estos mosaicos proceden de una villa cerca de Roma."
    r = await _write(admin, "es", revision, "pois/mosaics/text", new)
    assert r.status_code == 200 and [c["key"] for c in r.json()["changed"]] == ["pois/mosaics/text"]
    assert (await _texts(admin, "es"))["pois/mosaics/text"]["state"] == "current"
    # A cleared source text has nothing to translate; an emptied translation is missing.
    revision = (await _draft(admin))["revision"]
    r = await _write(admin, "es", revision, "tours/ground/name", "")
    assert r.status_code == 200
    assert (await _texts(admin, "es"))["tours/ground/name"]["state"] == "missing"
    # The draft with hashes is a valid site (and publishes).
    state = await _draft(admin)
    assert state["issues"] == []
    published = await admin.post("/api/site/publish", json={"revision": state["revision"]})
    assert published.status_code == 200, published.text


async def test_po_round_trip_marks_what_it_changed_against_the_source_it_came_from(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    r = await admin.get(f"{BASE}/de/export", params={"format": "po"})
    assert r.status_code == 200, r.text
    assert r.headers["content-disposition"] == 'attachment; filename="site-de.po"'
    po = pypo.pofile.parsestring(r.content)
    assert po.gettargetlanguage() == "de"
    units = {u.getcontext(): u for u in po.units if not u.isheader()}
    assert set(units) == set(await _texts(admin, "de"))
    assert units["pois/sword/name"].source == "Bronze Age sword"
    # The agency translates two texts and leaves the rest as they were.
    units["pois/sword/name"].target = "Bronzezeitliches Schwert"
    units["tours/ground/description"].target = "Fünf Stationen im Erdgeschoss."
    # Meanwhile the installer rewrites the tour's description in English.
    await _edit_source(admin, "sword", "text", "This sword is three thousand years old!")
    state = await _draft(admin)
    doc = state["draft"]
    ground = next(t for t in doc["tours"] if t["id"] == "ground")
    old_description = ground["description"]
    ground["description"] = "Five stops, from the Romans to the Bronze Age."
    r = await admin.put("/api/site/draft", json={"draft": doc, "revision": state["revision"]})
    assert r.status_code == 200
    r = await _import(admin, "de", bytes(po))
    assert r.status_code == 200, r.text
    report = r.json()
    changed = {c["key"]: c for c in report["changed"]}
    # The sword's text was exported from its old source: the same German, now marked stale.
    assert set(changed) == {"pois/sword/name", "tours/ground/description", "pois/sword/text"}
    sword_text = changed["pois/sword/text"]
    assert sword_text["before"] == sword_text["after"] and sword_text["stale"] is True
    assert changed["pois/sword/name"]["before"] == "Schwert aus der Bronzezeit"
    assert changed["pois/sword/name"]["after"] == "Bronzezeitliches Schwert"
    assert changed["pois/sword/name"]["stale"] is False
    # Translated from the description as it was at export: stale at once.
    assert changed["tours/ground/description"]["stale"] is True
    assert report["unchanged"] == len(units) - 3 - len(report["skipped"])
    assert report["revision"] == r.json()["revision"] == (await _draft(admin))["revision"]
    texts = await _texts(admin, "de")
    assert texts["pois/sword/name"]["state"] == "current"
    assert texts["tours/ground/description"]["state"] == "stale"
    assert texts["pois/sword/text"]["state"] == "stale"
    doc = (await _draft(admin))["draft"]
    tour_de = next(t for t in doc["tours"] if t["id"] == "ground")["translations"]["de"]
    assert tour_de["source_hash"]["description"] == source_hash(old_description)
    # The next export marks the stale ones fuzzy; a fuzzy unit is not imported.
    again = pypo.pofile.parsestring((await admin.get(f"{BASE}/de/export")).content)
    fuzzy = {u.getcontext() for u in again.units if u.isfuzzy()}
    assert fuzzy == {"tours/ground/description", "pois/sword/text"}
    r = await _import(admin, "de", bytes(again))
    assert r.status_code == 200 and r.json()["changed"] == []
    assert {s["key"] for s in r.json()["skipped"]} == fuzzy


async def test_xliff_round_trip_and_a_missing_text_filled(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    # A German text the demo lacks: the loom's description cleared in German.
    state = await _draft(admin)
    doc = state["draft"]
    del next(p for p in doc["pois"] if p["id"] == "loom")["translations"]["de"]["description"]
    r = await admin.put("/api/site/draft", json={"draft": doc, "revision": state["revision"]})
    assert r.status_code == 200
    assert (await _texts(admin, "de"))["pois/loom/description"]["state"] == "missing"
    r = await admin.get(f"{BASE}/de/export", params={"format": "xliff"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("application/x-xliff+xml")
    store = xliff.xlifffile.parsestring(r.content)
    assert (store.getsourcelanguage(), store.gettargetlanguage()) == ("en", "de")
    units = {u.getid().rsplit(xliff.ID_SEPARATOR, 1)[-1]: u for u in store.units}
    assert not units["pois/loom/description"].target
    units["pois/loom/description"].target = "So wurde Stoff von Hand gewebt, Faden für Faden."
    r = await _import(admin, "de", bytes(store), fmt="xliff")
    assert r.status_code == 200, r.text
    assert [(c["key"], c["before"]) for c in r.json()["changed"]] == [("pois/loom/description", "")]
    texts = await _texts(admin, "de")
    assert texts["pois/loom/description"]["state"] == "current"
    assert texts["pois/loom/description"]["translation"].endswith("Faden für Faden.")


XLIFF_EMPTY = (
    b'<?xml version="1.0"?><xliff xmlns="urn:oasis:names:tc:xliff:document:1.1" version="1.1">'
    b'<file original="s" source-language="en" datatype="plaintext"><body/></file></xliff>'
)
MALFORMED = [
    (
        "po",
        b'msgctxt "pois/sword/name"\nmsgid "Bronze Age sword\nmsgstr "x"\n',
        "not a readable PO",
    ),
    ("po", b"\x00\x01 not a po file", "not a readable PO file"),
    ("po", b'msgid "Bronze Age sword"\nmsgstr "Schwert"\n', "has no msgctxt"),
    ("po", b'msgctxt "a"\nmsgid "x"\nmsgstr "y"\n\nmsgctxt "a"\nmsgid "x"\nmsgstr "z"\n', "twice"),
    (
        "po",
        b'msgid ""\nmsgstr "Language: es\\n"\n\nmsgctxt "a"\nmsgid "x"\nmsgstr "y"\n',
        "'es', not",
    ),
    ("xliff", b"<xliff><file>", "not a readable XLIFF file"),
    ("xliff", b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e "boom">]><xliff>&e;</xliff>', "XLIFF"),
    ("xliff", XLIFF_EMPTY, "holds no texts"),
]


@pytest.mark.parametrize(("fmt", "raw", "says"), MALFORMED)
async def test_a_malformed_file_is_refused_whole_and_nothing_is_lost(
    server: RunningServer, http: Http, fmt: str, raw: bytes, says: str
) -> None:
    admin = http(server.admin_token)
    before = await _draft(admin)
    r = await _import(admin, "de", raw, fmt=fmt)
    assert r.status_code == 422, r.text
    assert says in r.json()["detail"]
    after = await _draft(admin)
    assert (after["revision"], after["draft"]) == (before["revision"], before["draft"])


async def test_a_po_file_for_the_language_s_region_is_taken(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    po = pypo.pofile.parsestring((await admin.get(f"{BASE}/de/export")).content)
    po.updateheader(Language="de_DE")
    next(u for u in po.units if u.getcontext() == "pois/sword/name").target = "Das Schwert"
    r = await _import(admin, "de", bytes(po))
    assert r.status_code == 200, r.text
    assert [c["after"] for c in r.json()["changed"]] == ["Das Schwert"]


async def test_refusals_stale_revision_source_language_unknown_language_and_roles(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    po = (await admin.get(f"{BASE}/es/export")).content
    revision = (await _draft(admin))["revision"]
    await _edit_source(admin, "sword", "name", "A Bronze Age sword")  # someone saves meanwhile
    r = await _import(admin, "es", po, revision=revision)
    assert r.status_code == 409 and "the draft was changed" in r.json()["detail"]["msg"]
    r = await admin.get(f"{BASE}/en")
    assert r.status_code == 422 and "default language" in r.json()["detail"]
    r = await admin.get(f"{BASE}/fr/export")
    assert r.status_code == 404 and "add it to the site's languages" in r.json()["detail"]
    r = await admin.get(f"{BASE}/de/export", params={"format": "docx"})
    assert r.status_code == 422
    r = await admin.put(f"{BASE}/de", json={"revision": "1", "texts": [{"key": "a", "text": "b"}]})
    assert r.status_code == 422  # strict: a revision is a number
    r = await http(OPERATOR_TOKEN).get(BASE)
    assert r.status_code == 403


def test_a_draft_with_odd_shapes_is_read_without_errors_and_unknown_keys_are_reported() -> None:
    doc: dict[str, Any] = {
        "name": "Odd",
        "default_language": "en",
        "languages": ["fr"],
        "pois": [
            {"id": "a", "name": "Hall", "translations": ["not", "a", "mapping"]},
            {"id": "b", "name": "Door", "lang": "fr", "translations": {}},
            "not a point",
            {"id": "c", "name": "Stairs", "text": "Mind the step."},
        ],
        "tours": None,
        "emergency": {"words": {"en": "Fire!"}},
    }
    keys = [e.key for e in text_entries(doc, "fr")]
    assert keys == ["pois/c/name", "pois/c/text", "emergency/words"]
    assert summary(doc) == [{"lang": "fr", "missing": 3, "stale": 0, "current": 0, "total": 3}]
    new, report = apply_translations(
        doc,
        "fr",
        [
            ("pois/c/name", "Escalier", None),
            ("emergency/words", "Au feu !", "Fire"),  # translated from an older source
            ("pois/b/name", "Porte", None),
            ("pois/zz/name", "?", None),
        ],
    )
    assert [(c.key, c.stale) for c in report.changed] == [
        ("pois/c/name", False),
        ("emergency/words", True),
    ]
    assert [s.key for s in report.skipped] == ["pois/b/name", "pois/zz/name"]
    assert "its source is in 'fr'" in report.skipped[0].reason
    assert "no such text" in report.skipped[1].reason
    assert new["emergency"]["words_source_hash"] == {"fr": source_hash("Fire")}
    assert "translations" not in doc["pois"][3]  # the input is left as it was
    # Cleared again: no empty leftovers in the document.
    cleared, _ = apply_translations(new, "fr", [("pois/c/name", "", None)])
    assert "translations" not in cleared["pois"][3]


def test_a_site_file_with_hashes_is_valid_and_site_check_warns_of_a_stale_one(
    tmp_path: Path,
) -> None:
    doc = yaml.safe_load(DEMO.read_text())
    poi = doc["pois"][0]
    poi["translations"]["es"]["source_hash"] = {"text": source_hash(poi["text"])}
    validate_site(doc)
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(doc, allow_unicode=True))
    check = ["check", str(path), "--deadlock-robots", "0"]
    result = CliRunner().invoke(site_cli, check)
    assert result.exit_code == 0 and "older than its source" not in result.output
    poi["translations"]["es"]["source_hash"] = {"text": source_hash("an older text")}
    path.write_text(yaml.safe_dump(doc, allow_unicode=True))
    result = CliRunner().invoke(site_cli, check)
    assert result.exit_code == 0, result.output
    assert (
        f"warning: pois/{poi['id']}/text in 'es': older than its source: the source text changed"
        in result.output
    )
    poi["translations"]["es"]["source_hash"] = {"text": "not-a-hash"}
    with pytest.raises(Exception, match="source_hash"):
        validate_site(doc)
