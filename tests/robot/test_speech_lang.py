"""Speech in the visitor's language: espeak-ng's voice for the tag (or its base language), the
timed fallback for a language it has no voice for, and the language on the speech events."""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import AsyncIterator
from typing import Any

import pytest

from guidebot.bus import Bus
from robot_agent.clock import Clock
from robot_agent.speech import Speech, voice_for

pytestmark = pytest.mark.timeout(30)


@contextlib.asynccontextmanager
async def speaking(helpers: Any) -> AsyncIterator[tuple[Bus, Speech, Any]]:
    """espeak-ng's speech on a bus of its own (the test skips where it is not installed): the
    bus, the speech and a recorder of its ``speech_*`` events; stopped at the end."""
    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng not installed (make system-deps)")
    bus = Bus()
    speech = Speech(bus.endpoint("speech"), Clock(100.0))
    await speech.start()
    try:
        yield bus, speech, helpers.Recorder(bus.endpoint("t"), "speech_*")
    finally:
        await speech.stop()


def test_voice_for_takes_the_tag_then_its_base_language() -> None:
    voices = frozenset({"en", "en-us", "es", "es-419"})
    assert voice_for("es", voices) == "es"
    assert voice_for("en-US", voices) == "en-us"
    assert voice_for("es-MX", voices) == "es"
    assert voice_for("xx", voices) is None


async def test_spanish_is_spoken_with_the_spanish_voice_and_unknown_languages_are_timed(
    helpers: Any,
) -> None:
    async with speaking(helpers) as (bus, _, seen):
        net = bus.endpoint("net")
        net.publish("say", {"text": "Bienvenidos al museo.", "lang": "es"})
        await seen.wait_for(lambda: seen.of("speech_ended"))
        started = seen.of("speech_started")[0].payload
        assert started == {"text": "Bienvenidos al museo.", "lang": "es", "voice": "es"}
        net.publish("say", {"text": "Klaatu barada nikto.", "lang": "xx"})
        await seen.wait_for(lambda: len(seen.of("speech_ended")) == 2)
        ended = seen.of("speech_ended")[1].payload
        assert ended["lang"] == "xx" and ended["voice"] is None and ended["outcome"] == "done"


def test_a_language_espeak_has_only_regionally_is_asked_by_its_base_language() -> None:
    """espeak-ng lists English only by region (en-029 first by name, Caribbean) and resolves
    ``-v en`` to its own first choice (British): the base is asked for, never the first tag."""
    voices = frozenset({"fr-fr", "fr-be", "de", "en-029", "en-gb", "en-us"})
    assert voice_for("fr", voices) == "fr"
    assert voice_for("en", voices) == "en"
    assert voice_for("en-US", voices) == "en-us"
    assert voice_for("de-AT", voices) == "de"
    assert voice_for("it", voices) is None


async def test_german_the_demo_s_third_language_has_its_voice_and_a_slower_tour_speaks_slower(
    helpers: Any,
) -> None:
    async with speaking(helpers) as (bus, speech, seen):
        text = "Diese Mosaike stammen aus einer römischen Villa."  # sites/demo_museum.yaml
        bus.endpoint("net").publish("say", {"text": text, "lang": "de"})
        await seen.wait_for(lambda: seen.of("speech_ended"))
        assert seen.of("speech_started")[0].payload == {"text": text, "lang": "de", "voice": "de"}
        usual = await speech._duration(text, "de")
        speech.dwell = 1.5  # a slower tour (robot_agent/visitor_needs.py)
        slower = await speech._duration(text, "de")
        print(f"espeak-ng de: {usual:.2f} s, slower {slower:.2f} s ({slower / usual:.2f} times)")
        assert 1.3 <= slower / usual <= 1.7
