"""Nets published from the editor installed in a library (docs/nets.md, "Publish"): all or
none, refused when a net that uses them would break, and a task started before an install
finishes on the versions it started with (its sub-nets too) while the next one takes the new."""

from __future__ import annotations

from guidebot.bus import Bus
from petri_nets.clock import VirtualClock
from petri_nets.dispatch import Dispatch
from petri_nets.library import NetLibrary
from petri_nets.netjson import EditorNet, doc_to_editor, editor_to_pnml
from petri_nets.scripted import DEFAULT_REPLIES, ScriptedEnvironment

NEW_WORDS = '{"text": "New words: ${text}", "lang": "${lang}"}'


def explain_point_saying(library: NetLibrary, body: str, *, required: str | None = None) -> bytes:
    doc = doc_to_editor(library.get("explain_point").doc)
    next(p for p in doc["places"] if p["id"] == "synthesize_text")["action"]["body"] = body
    if required:
        doc["params"].append({"name": required, "required": True, "default": None})
    return editor_to_pnml(EditorNet.model_validate(doc))


def test_a_running_task_keeps_its_versions_and_the_next_one_takes_the_new() -> None:
    library = NetLibrary(watch=False)
    bus = Bus()
    clock = VirtualClock()
    environment = ScriptedEnvironment(bus, clock, DEFAULT_REPLIES)
    dispatch = Dispatch(bus.endpoint("dispatch"), library, clock, idle_net=None)
    dispatch.open()
    # go_to_poi navigates for 10 s, then runs explain_point: installed meanwhile.
    dispatch.start("go_to_poi", {"node": "n1", "text": "before"})
    clock.advance(5.0)
    assert library.install({"explain_point": explain_point_saying(library, NEW_WORDS)}) == []
    dispatch.start("go_to_poi", {"node": "n2", "text": "after"})
    clock.run(until=200.0)
    said = [m.payload["text"] for m in environment.seen if m.type == "say"]
    assert said == ["before", "New words: after"]
    assert dispatch.running() == []


def test_an_install_that_breaks_a_caller_or_does_not_run_changes_nothing() -> None:
    library = NetLibrary(watch=False)
    shipped = library.get("explain_point")
    stricter = explain_point_saying(library, NEW_WORDS, required="voice")
    problems = library.install({"explain_point": stricter})
    assert problems and all("voice" in str(p) for p in problems)
    assert {p.file.split("/")[-1] for p in problems} >= {"give_tour.pnml", "go_to_poi.pnml"}
    assert library.get("explain_point") is shipped
    # All or none: a good net beside a broken file installs neither.
    good = explain_point_saying(library, NEW_WORDS)
    assert library.install({"explain_point": good, "blink": b"<pnml>"}) != []
    assert library.get("explain_point") is shipped and library.installed == {}
    assert library.install({"explain_point": good}) == []
    assert library.get("explain_point") is not shipped
    assert library.get("explain_point", {}) is shipped  # what a task started before sees
