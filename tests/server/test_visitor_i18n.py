"""Site texts per language: fallback field by field to the default language, warnings for
texts missing in a declared language (``guidebot site check``), and the task's language on the
robot's net parameters."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from click.testing import CliRunner

from backend.site.cli import site as site_cli
from guidebot.site.i18n import (
    fallbacks,
    missing_translations,
    poi_texts,
    site_languages,
    tour_texts,
)
from guidebot.site.schema import Site
from guidebot.site.validate import SiteInvalid, validate_site
from guidebot.site.yamlio import load_site_file

ROOT = Path(__file__).resolve().parents[2]

DOC: dict[str, Any] = {
    "name": "Two languages",
    "default_language": "en",
    "languages": ["es", "fr"],
    "floors": [{"id": "F0"}],
    "nodes": [{"id": "a", "floor": "F0", "x": 0, "y": 0}],
    "pois": [
        {
            "id": "vase",
            "name": "Vase",
            "node": "a",
            "text": "A vase.",
            "media": ["vase.jpg"],
            "translations": {
                "es": {"name": "Jarrón", "text": "Un jarrón.", "media": ["jarron.jpg"]}
            },
        }
    ],
    "tours": [
        {
            "id": "t",
            "name": "Tour",
            "description": "Short.",
            "points": ["vase"],
            "translations": {"es": {"name": "Visita"}},
        }
    ],
}


def test_a_missing_translation_falls_back_to_the_default_language_field_by_field() -> None:
    site = Site.model_validate(DOC)
    assert site_languages(site) == ["en", "es", "fr"]
    es = poi_texts(site, site.pois[0], "es")
    assert es == {
        "name": "Jarrón",
        "description": "Un jarrón.",
        "text": "Un jarrón.",
        "media": ["jarron.jpg"],
        "lang": "es",
    }
    fr = poi_texts(site, site.pois[0], "fr")
    assert fr["name"] == "Vase" and fr["text"] == "A vase." and fr["lang"] == "en"
    assert poi_texts(site, site.pois[0], "de")["name"] == "Vase"  # not offered: the default
    assert tour_texts(site, site.tours[0], "es") == {"name": "Visita", "description": "Short."}


def test_each_text_that_falls_back_is_named_with_the_language_it_is_shown_in() -> None:
    site = Site.model_validate(DOC)
    # What a page marks (``lang``) and tells the visitor (docs/visitor.md, "Languages").
    assert fallbacks(site, site.pois[0], "es") == {}
    assert fallbacks(site, site.pois[0], "fr") == {"name": "en", "text": "en"}
    assert fallbacks(site, site.pois[0], "en") == {}
    assert fallbacks(site, site.tours[0], "es") == {"description": "en"}
    assert fallbacks(site, site.tours[0], "fr") == {"name": "en", "description": "en"}


def test_texts_missing_in_a_declared_language_are_warnings_with_their_place() -> None:
    site = Site.model_validate(DOC)
    places = {issue.loc for issue in missing_translations(site)}
    assert "tours[0].translations.es.description" in places
    assert "pois[0].translations.fr.text" in places
    assert "pois[0].translations.es.text" not in places


def test_a_bad_language_tag_is_an_error() -> None:
    doc = dict(DOC, languages=["Spanish"])
    try:
        validate_site(doc)
    except SiteInvalid as exc:
        assert any(i.loc.startswith("languages") for i in exc.issues)
    else:
        raise AssertionError("a bad tag was accepted")


def test_site_check_prints_warnings_and_still_accepts(tmp_path: Path) -> None:
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(DOC))
    result = CliRunner().invoke(site_cli, ["check", str(path)])
    assert result.exit_code == 0, result.output
    assert "warning: pois[0].translations.fr.name: missing in 'fr'" in result.output
    assert "warning(s)" in result.output


def test_the_demo_museum_has_english_spanish_and_german_complete() -> None:
    site = load_site_file(ROOT / "sites" / "demo_museum.yaml")
    assert site_languages(site) == ["en", "es", "de"]
    assert missing_translations(site) == []
