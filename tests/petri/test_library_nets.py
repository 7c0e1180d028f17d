"""The paper's examples, step by step, on the shipped library."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from petri_nets import library_source
from petri_nets.describe import describe
from petri_nets.library import NetLibrary
from petri_nets.scripted import DEFAULT_REPLIES

from .rig import TOUR_POINTS, Rig, make_rig


def test_library_is_valid_and_complete() -> None:
    library = NetLibrary()
    assert library.problems() == []
    assert set(library.names()) >= {
        "wink_one_eye",
        "blink",
        "head_talk",
        "face_people",
        "rest_expression",
        "explain_point",
        "navigate_to_point",
        "give_tour",
        "go_to_poi",
        "battery_charge",
        "waiting",
    }


def test_every_library_file_is_what_its_source_writes(tmp_path: Path) -> None:
    """The .pnml files are generated (``python -m petri_nets.library_source``): a hand edit of
    one (go_to_poi's ``lang``) was lost on the next regeneration. Edit the source, then run it."""
    library = Path(library_source.__file__).with_name("library")
    written = {p.name: p.read_bytes() for p in library_source.write_library(tmp_path)}
    shipped = {p.name: p.read_bytes() for p in library.glob("*.pnml")}
    assert sorted(shipped) == sorted(written)
    stale = [name for name in written if shipped[name] != written[name]]
    assert not stale, f"{stale} differ from petri_nets/library_source.py: edit it, then run it"


def test_wink_one_eye_moves_servos_in_the_paper_order(rig: Rig) -> None:
    iid = rig.dispatch.start("wink_one_eye", {"eye": "eyelid_left"})
    assert rig.published("move_servos") == [
        {"servos": {"eyelid_left": 0.0, "eyelid_right": 0.0}, "speed": 180.0}
    ]
    rig.say("servo_in_position", servo="eyelid_right", position=0.0)
    rig.say("servo_in_position", servo="eyelid_left", position=0.0)
    # both eyes open: the wait place holds the mark for hold_s
    assert rig.dispatch.get(iid).marking() == {"wait": 1}  # type: ignore[union-attr]
    rig.clock.advance(0.49)
    assert len(rig.published("move_servos")) == 1
    rig.clock.advance(0.02)
    assert rig.published("move_servos")[1] == {"servos": {"eyelid_left": 60.0}, "speed": 180.0}
    rig.say("servo_in_position", servo="eyelid_right", position=0.0)  # not the winked eye
    assert len(rig.published("move_servos")) == 2
    rig.say("servo_in_position", servo="eyelid_left", position=60.0)
    assert rig.published("move_servos")[2] == {"servos": {"eyelid_left": 0.0}, "speed": 180.0}
    assert rig.ended(iid) is None
    rig.say("servo_in_position", servo="eyelid_left", position=0.0)
    assert rig.ended(iid) == "done"
    assert rig.fired(iid) == [
        "eyes_moving",
        "r_opened",
        "l_opened",
        "both_open",
        "end_wait",
        "eye_closed",
        "eye_opened",
    ]


def test_explain_point_kills_head_talk_when_speech_ends(rig: Rig) -> None:
    iid = rig.dispatch.start("explain_point", {"text": "Hello visitors"})
    assert rig.action_types() == ["face_people"]
    rig.say("people_faced")
    assert rig.published("say") == [{"text": "Hello visitors", "lang": "en"}]
    talk = [r for r in rig.dispatch.running() if r["net"] == "head_talk"]
    assert len(talk) == 1 and talk[0]["parent"] == iid
    rig.clock.advance(2.0)  # the head keeps talking while the speech lasts
    mouth_moves = [p for p in rig.published("move_servos") if "mouth" in p["servos"]]
    assert len(mouth_moves) >= 8
    rig.say("speech_ended", text="Hello visitors")
    assert rig.ended(talk[0]["instance_id"]) == "killed"
    rest = rig.published("move_servos")[-1]["servos"]
    assert rest == {"eyelid_left": 0.0, "eyelid_right": 0.0, "mouth": 0.0}
    for servo, position in rest.items():
        rig.say("servo_in_position", servo=servo, position=position)
    assert rig.ended(iid) == "done"
    moves_after = len(rig.published("move_servos"))
    rig.clock.advance(5.0)
    assert len(rig.published("move_servos")) == moves_after  # head_talk really stopped
    assert rig.dispatch.running() == []


def tour_rig(answer: str | None, navigation: str = "goal_reached", *, closed: bool = False) -> Rig:
    replies = copy.deepcopy(DEFAULT_REPLIES)
    replies["ask_continue"] = (
        []
        if answer is None
        else [{"type": "continue_answer", "payload": {"answer": answer}, "delay": 1.0}]
    )
    if navigation != "goal_reached":
        reason = "gallery g closed: cleaning" if closed else "blocked"
        failed = {"node": "${node}", "reason": reason, "closed": closed}
        replies["navigate_to"] = [{"type": "navigation_failed", "payload": failed}]
    return make_rig(replies=replies)


@pytest.mark.parametrize("answer", ["no", "timeout"])
def test_give_tour_ends_when_the_visitor_says_no_or_the_gui_times_out(answer: str) -> None:
    rig = tour_rig(answer)
    iid = rig.dispatch.start("give_tour", {"tour": "t1", "points": TOUR_POINTS}, main=True)
    rig.run()
    assert rig.ended(iid) == "done"
    assert [p["node"] for p in rig.published("navigate_to")] == ["n1"]
    assert len(rig.published("ask_continue")) == 1
    assert rig.fired(iid)[-1] == f"answer_{answer}"
    assert rig.dispatch.running() == []


def test_give_tour_ends_when_nobody_answers() -> None:
    rig = tour_rig(None)
    iid = rig.dispatch.start("give_tour", {"tour": "t1", "points": TOUR_POINTS, "patience_s": 30.0})
    rig.run()
    assert rig.ended(iid) == "done"
    assert rig.fired(iid)[-1] == "no_answer"
    fired_at = {
        m.payload["transition"]: m.payload["time"]
        for m in rig.log
        if m.type == "petri_net_event"
        and m.payload["instance_id"] == iid
        and m.payload["kind"] == "fired"
    }
    assert fired_at["no_answer"] - fired_at["more_points"] == pytest.approx(30.0)


def test_give_tour_visits_every_point_and_asks_between_them() -> None:
    rig = tour_rig("yes")
    iid = rig.dispatch.start("give_tour", {"tour": "t1", "points": TOUR_POINTS})
    rig.run()
    assert rig.ended(iid) == "done"
    assert [p["node"] for p in rig.published("navigate_to")] == ["n1", "n2", "n3"]
    assert [p["poi"] for p in rig.published("show_point")] == ["p1", "p2", "p3"]
    assert [p["text"] for p in rig.published("say")] == [p["text"] for p in TOUR_POINTS]
    assert len(rig.published("ask_continue")) == 2  # not after the last point
    assert rig.fired(iid)[-1] == "last_point_done"


def test_give_tour_fails_when_navigation_fails() -> None:
    rig = tour_rig("yes", navigation="navigation_failed")
    iid = rig.dispatch.start("give_tour", {"tour": "t1", "points": TOUR_POINTS})
    rig.run()
    assert rig.ended(iid) == "failed"
    assert rig.published("show_point") == []


def test_battery_charge_docks_and_waits_until_charged() -> None:
    rig = make_rig(replies=copy.deepcopy(DEFAULT_REPLIES))
    iid = rig.dispatch.start("battery_charge", {"node": "dock1", "station": "s1"})
    rig.clock.advance(30)
    assert rig.published("dock") == [{"station": "s1"}]
    assert rig.ended(iid) is None
    rig.run()
    assert rig.ended(iid) == "done"


def test_waiting_is_killed_by_a_main_task_and_restarted_after() -> None:
    rig = make_rig(replies=copy.deepcopy(DEFAULT_REPLIES), idle_net="waiting")
    waiting = [r for r in rig.dispatch.running() if r["net"] == "waiting"]
    assert len(waiting) == 1
    rig.clock.advance(60)  # random gestures while idle
    assert rig.published("move_servos")
    # the params exactly as the Task Manager sends them in task_assigned
    params = {"poi": "p5", "node": "n5", "text": "The fountain."}
    task = rig.dispatch.start("go_to_poi", params, main=True)
    assert rig.ended(waiting[0]["instance_id"]) == "killed"
    assert {r["net"] for r in rig.dispatch.running() if r["parent"] is None} == {"go_to_poi"}
    rig.clock.advance(60)
    assert rig.ended(task) == "done"
    assert rig.published("show_point") == [{"poi": "p5", "text": "The fountain.", "lang": "en"}]
    assert rig.published("say")[-1]["text"] == "The fountain."
    again = [r for r in rig.dispatch.running() if r["net"] == "waiting"]
    assert len(again) == 1 and again[0]["instance_id"] != waiting[0]["instance_id"]


def test_describe_gives_a_gui_everything_to_draw_a_net() -> None:
    net = NetLibrary().get("give_tour")
    described = describe(net)
    json.dumps(described)  # JSON-ready
    assert described["version"] == net.version
    assert described["required"] == ["tour", "points"]
    places = {p["id"]: p for p in described["places"]}
    assert places["navigation_failed"]["outcome"] == "failed"
    assert places["ask_continue"]["action"] == "publish"
    assert places["ask_continue"]["position"] is not None
    answers = {t["id"]: t for t in described["transitions"]}
    assert answers["answer_no"]["detail"] == "continue_answer answer=no"
    assert len(described["arcs"]) == len(net.doc.arcs)


def test_give_tour_skips_a_point_only_closed_elements_lead_to_and_goes_on() -> None:
    """Building modes and trouble (issue 36): navigation says the point is closed off; the tour
    says point_skipped with the reason, asks nothing, and goes on to the next point."""
    rig = tour_rig("yes", navigation="navigation_failed", closed=True)
    iid = rig.dispatch.start("give_tour", {"tour": "t1", "points": TOUR_POINTS})
    rig.run()
    assert rig.ended(iid) == "done"
    assert [p["node"] for p in rig.published("navigate_to")] == ["n1", "n2", "n3"]
    skipped = rig.published("point_skipped")
    assert [(s["point"]["node"], s["reason"]) for s in skipped] == [
        ("n1", "gallery g closed: cleaning"),
        ("n2", "gallery g closed: cleaning"),
        ("n3", "gallery g closed: cleaning"),
    ]
    assert rig.published("show_point") == [] and rig.published("ask_continue") == []
    assert rig.fired(iid)[-1] == "skipped_last"


def test_a_point_visit_speaks_and_shows_in_its_visitors_language() -> None:
    """go_to_poi ran explain_point without ``lang``: a Spanish visitor's "take me there" was
    said with the English voice. The language the server gives the visit reaches the speech
    and the screen."""
    rig = make_rig(replies=copy.deepcopy(DEFAULT_REPLIES))
    text = "Esta espada tiene tres mil años."
    params = {"node": "n1", "poi": "sword", "text": text, "lang": "es"}
    iid = rig.dispatch.start("go_to_poi", params, main=True)
    rig.run()
    assert rig.ended(iid) == "done"
    assert rig.published("say") == [{"text": text, "lang": "es"}]
    assert [p["lang"] for p in rig.published("show_point")] == ["es"]
