"""The site editor's translations (issue 41, for the installer): per language the texts missing
or older than their source, edited beside the source, and a PO file exported, translated by
"an agency" and imported back, in a real browser against a real server."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect
from translate.storage import pypo

from tests.web.test_config import open_editor

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

BASE = "/api/site/draft/translations"


async def _stale_and_missing_german(fleet: Any) -> None:
    """The mosaics' German text translated from the current English (its hash recorded), then
    the English rewritten: older than its source; the loom's German description removed."""
    async with fleet.http() as http:
        state = (await http.get("/api/site/draft")).json()
        doc = state["draft"]
        mosaics = next(p for p in doc["pois"] if p["id"] == "mosaics")
        text = {"key": "pois/mosaics/text", "text": mosaics["translations"]["de"]["text"]}
        r = await http.put(f"{BASE}/de", json={"revision": state["revision"], "texts": [text]})
        assert r.status_code == 200, r.text
        state = (await http.get("/api/site/draft")).json()
        doc = state["draft"]
        next(p for p in doc["pois"] if p["id"] == "mosaics")["text"] = (
            "These mosaics come from a villa near Rome."
        )
        del next(p for p in doc["pois"] if p["id"] == "loom")["translations"]["de"]["description"]
        r = await http.put("/api/site/draft", json={"draft": doc, "revision": state["revision"]})
        assert r.status_code == 200, r.text


async def test_missing_and_stale_counts_side_by_side_edit_and_a_po_round_trip(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, tmp_path: Path
) -> None:
    async with fleet_factory(robots=0) as fleet:
        await _stale_and_missing_german(fleet)
        watch = await open_editor(open_page, fleet)
        watch.expect_error(r"status of 422")  # the malformed file at the end
        page = watch.page
        await page.get_by_role("button", name="Translations").click()
        await expect(page.get_by_label("Floor plan editor")).to_be_hidden()
        languages = page.get_by_role("table", name="Texts per language")
        german = languages.locator("tr[data-lang=de]")
        await expect(german).to_contain_text("German (de)")
        await expect(german.locator("td").nth(0)).to_have_text("1")  # missing
        await expect(german.locator("td").nth(1)).to_have_text("1")  # older than its source
        spanish = languages.locator("tr[data-lang=es]")
        await expect(spanish.locator("td").nth(0)).to_have_text("0")
        await expect(spanish.locator("td").nth(1)).to_have_text("0")
        await web.axe_check(page)

        # Side by side: the two German texts to do, each beside its English source.
        await german.get_by_role("button", name="Translate German").click()
        texts = page.get_by_role("table", name="German (de)")
        rows = texts.locator("tbody tr")
        await expect(rows).to_have_count(2)
        stale = texts.locator('tr[data-key="pois/mosaics/text"]')
        await expect(stale.locator("td.source")).to_have_text(
            "These mosaics come from a villa near Rome."
        )
        await expect(stale.locator("td.source")).to_have_attribute("lang", "en")
        await expect(stale.locator("td.state")).to_contain_text("Older than its source")
        missing = texts.locator('tr[data-key="pois/loom/description"]')
        await expect(missing.locator("td.state")).to_contain_text("Missing")
        await web.axe_check(page)
        await web.screenshot(page, "config-translations")
        box = page.get_by_role("textbox", name="Point Loom (loom): description in German")
        await expect(box).to_have_attribute("lang", "de")
        await box.fill("So wurde Stoff von Hand gewebt.")
        await box.press("Tab")  # a change is saved when the box is left
        await expect(missing).to_have_count(0)  # done: the filter shows what is left
        await expect(german.locator("td").nth(0)).to_have_text("0")
        # The mosaics' German still fits the new English: the translator keeps it.
        await stale.get_by_role("button", name="still right").click()
        await expect(german.locator("td").nth(1)).to_have_text("0")
        done = page.get_by_text("Every text is translated from its current source.")
        await expect(done).to_be_visible()
        async with fleet.http() as http:
            by_key = {t["key"]: t for t in (await http.get(f"{BASE}/de")).json()["texts"]}
        assert by_key["pois/loom/description"]["translation"] == "So wurde Stoff von Hand gewebt."
        assert {t["state"] for t in by_key.values()} == {"current"}

        # The agency's round trip: export the PO file, translate, import it back.
        async with page.expect_download() as download:
            await page.get_by_role("button", name="Export de as PO").click()
        exported = tmp_path / (await download.value).suggested_filename
        assert exported.name == "site-de.po"
        await (await download.value).save_as(exported)
        po = pypo.pofile.parsestring(exported.read_bytes())
        sword = next(u for u in po.units if u.getcontext() == "pois/sword/name")
        assert (sword.source, sword.target) == ("Bronze Age sword", "Schwert aus der Bronzezeit")
        sword.target = "Bronzezeitliches Schwert"
        await page.get_by_label("Import a translated PO or XLIFF file").set_input_files(
            files=[{"name": "site-de.po", "mimeType": "text/x-po", "buffer": bytes(po)}]
        )
        changed = page.get_by_role("list", name="Changed texts")
        await expect(changed).to_contain_text(
            "Point Bronze Age sword (sword): name: "
            "Schwert aus der Bronzezeit → Bronzezeitliches Schwert"
        )
        imported = page.get_by_role("status").filter(has_text="site-de.po imported")
        await expect(imported).to_contain_text("1 text changed")
        await page.get_by_role("radio", name="All texts").check()
        await expect(texts.locator('tr[data-key="pois/sword/name"] textarea')).to_have_value(
            "Bronzezeitliches Schwert"
        )
        await web.axe_check(page)

        # A broken file is refused whole: the page says why and nothing changes.
        draft = page.locator("#draft-status")
        revision = await draft.inner_text()
        await page.get_by_label("Import a translated PO or XLIFF file").set_input_files(
            files=[{"name": "broken.po", "mimeType": "text/x-po", "buffer": b'msgid "oops\n'}]
        )
        await expect(page.get_by_role("alert")).to_contain_text(
            "broken.po refused, nothing was changed: not a readable PO file"
        )
        await expect(draft).to_have_text(revision)
        await web.axe_check(page)
        # A new language: every text missing until translated.
        await page.get_by_label("Add a language").fill("fr")
        await page.get_by_role("button", name="Add language").click()
        french = languages.locator("tr[data-lang=fr]")
        await expect(french).to_contain_text("French (fr)")
        async with fleet.http() as http:
            overview = (await http.get("/api/site/draft/translations")).json()
        total = overview["languages"][0]["total"]
        await expect(french.locator("td").nth(0)).to_have_text(str(total))
        await expect(
            page.get_by_role("table", name="French (fr)").locator("tbody tr")
        ).to_have_count(total)
        async with fleet.http() as http:
            assert (await http.get("/api/site/draft")).json()["draft"]["languages"][-1] == "fr"
        # Back to the plan.
        await page.get_by_role("button", name="Plan and elements").click()
        await expect(page.get_by_label("Floor plan editor")).to_be_visible()
        # Publishing with French untranslated warns, and is not refused.
        await page.get_by_role("button", name="Publish", exact=True).click()
        published = page.get_by_role("status").filter(has_text="Not yet translated")
        await expect(published).to_contain_text(
            f"Version 2 is live. Not yet translated: French {total} missing, 0 older than their "
            "source; visitors get English for them (see Translations)."
        )
        async with fleet.http() as http:
            assert (await http.get("/api/site")).json()["site"]["languages"][-1] == "fr"
