"""Firing semantics: conflicts, weights, timers, events, parameters, nested kill, monitoring."""

from __future__ import annotations

from pathlib import Path

import pytest

from petri_nets.builder import (
    NetBuilder,
    guard,
    message,
    net_ended,
    publish,
    run,
    timer,
    timer_elapsed,
)
from petri_nets.dispatch import DispatchError
from petri_nets.model import NetDoc
from petri_nets.pnml import write_pnml

from .rig import Rig, make_rig


def rig_with(tmp_path: Path, *docs: NetDoc) -> Rig:
    for doc in docs:
        (tmp_path / f"{doc.id}.pnml").write_bytes(write_pnml(doc))
    return make_rig(tmp_path)


def choice(priority_b: int = 0) -> NetDoc:
    b = NetBuilder("choice")
    b.place("p0", initial=1).place("pa", final=True).place("pb", final=True)
    b.transition("ta", ["p0"], ["pa"]).transition("tb", ["p0"], ["pb"], priority=priority_b)
    return b.build()


def test_conflict_goes_to_the_first_transition_in_document_order(tmp_path: Path) -> None:
    rig = rig_with(tmp_path, choice())
    iid = rig.dispatch.start("choice")
    assert rig.fired(iid) == ["ta"]
    assert rig.ended(iid) == "done"


def test_priority_overrides_document_order(tmp_path: Path) -> None:
    rig = rig_with(tmp_path, choice(priority_b=1))
    iid = rig.dispatch.start("choice")
    assert rig.fired(iid) == ["tb"]


def test_one_message_fires_one_transition_the_first_that_matches(tmp_path: Path) -> None:
    b = NetBuilder("answers")
    b.place("wait_a", initial=1).place("wait_b", initial=1)
    b.place("a", final=True).place("b", final=True).place("c", final=True)
    b.transition("wrong_field", ["wait_a"], ["c"], message("ping", who="nobody"))
    b.transition("first", ["wait_a"], ["a"], message("ping", who="me"))
    b.transition("second", ["wait_b"], ["b"], message("ping", who="me"))
    rig = rig_with(tmp_path, b.build())
    iid = rig.dispatch.start("answers")
    rig.say("ping", who="me")
    assert rig.fired(iid) == ["first"]
    rig.say("ping", who="me")
    assert rig.fired(iid) == ["first", "second"]
    assert rig.ended(iid) == "done"


def test_arc_weights_consume_and_produce_several_marks(tmp_path: Path) -> None:
    b = NetBuilder("weights")
    b.place("stock", initial=5).place("beep", action=publish("beep", {"n": 1}))
    b.place("left", final=True)
    b.transition("take_two", {"stock": 2}, {"beep": 3})
    b.transition("beeped", {"beep": 3}, {"left": 1}, message("go"))
    rig = rig_with(tmp_path, b.build())
    iid = rig.dispatch.start("weights")
    assert rig.fired(iid) == ["take_two", "take_two"]  # 5 marks: twice, 1 left
    assert len(rig.published("beep")) == 6  # the action runs once per mark received
    instance = rig.dispatch.get(iid)
    assert instance is not None and instance.marking() == {"stock": 1, "beep": 6}
    rig.say("go")
    rig.say("go")
    assert instance.marking() == {"stock": 1, "left": 2}
    assert rig.ended(iid) is None  # a mark is still in a non-final place


def test_a_timer_place_holds_its_mark_until_the_timer_elapses(tmp_path: Path) -> None:
    b = NetBuilder("hold", params={"seconds": 5})
    b.place("wait", initial=1, action=timer("${seconds}")).place("out", final=True)
    b.transition("go_on", ["wait"], ["out"])  # unconditioned, but the mark is held
    rig = rig_with(tmp_path, b.build())
    iid = rig.dispatch.start("hold", {"seconds": 2})
    rig.clock.advance(1.99)
    assert rig.ended(iid) is None
    rig.clock.advance(0.02)
    assert rig.ended(iid) == "done"


def test_a_message_can_take_a_held_mark_and_cancels_its_timer(tmp_path: Path) -> None:
    b = NetBuilder("race")
    b.place("ask", initial=1, action=publish("question", {}))
    b.place("patience", initial=1, action=timer(10))
    b.place("answered", final=True).place("timed_out", final=True, outcome="failed")
    b.transition("answer", ["ask", "patience"], ["answered"], message("answer"))
    b.transition("too_late", ["ask", "patience"], ["timed_out"], timer_elapsed())
    rig = rig_with(tmp_path, b.build())
    first = rig.dispatch.start("race")
    rig.clock.advance(3)
    rig.say("answer")
    assert rig.ended(first) == "done"
    second = rig.dispatch.start("race")
    rig.clock.advance(20)
    assert rig.ended(second) == "failed"
    assert rig.fired(second) == ["too_late"]


def test_replies_published_inline_by_an_action_are_not_lost(tmp_path: Path) -> None:
    b = NetBuilder("echo")
    b.place("ask", initial=1, action=publish("echo_request", {"x": 1}))
    b.place("done", final=True)
    b.transition("echoed", ["ask"], ["done"], message("echo_reply", x=1))
    rig = rig_with(tmp_path, b.build())
    rig.client.subscribe("echo_request", lambda m: rig.say("echo_reply", **m.payload))
    iid = rig.dispatch.start("echo")
    assert rig.ended(iid) == "done"


def test_parameters_defaults_types_and_interpolation(tmp_path: Path) -> None:
    b = NetBuilder("greet", params={"count": 2, "lang": "en"}, required=("name",))
    b.place(
        "hello",
        initial=1,
        final=True,
        action=publish(
            "say",
            {
                "text": "Hello ${name}, ${count} times",
                "lang": "${lang}",
                "n": "${count}",
                "whole": "${name}",
            },
        ),
    )
    rig = rig_with(tmp_path, b.build())
    rig.dispatch.start("greet", {"name": {"first": "Ada"}, "count": 3})
    assert rig.published("say") == [
        {"text": "Hello {'first': 'Ada'}, 3 times", "lang": "en", "n": 3, "whole": {"first": "Ada"}}
    ]
    with pytest.raises(DispatchError, match=r"missing parameter.*name"):
        rig.dispatch.start("greet", {})
    extra = rig.dispatch.start("greet", {"name": "x", "colour": "red"})  # more is fine
    assert rig.ended(extra) == "done"
    assert rig.dispatch.running() == []


def nested() -> list[NetDoc]:
    leaf = NetBuilder("leaf").place("w", initial=1).place("e", final=True)
    leaf.transition("t", ["w"], ["e"], message("never"))
    middle = NetBuilder("middle").place("go", initial=1, action=run("leaf"))
    middle.place("e", final=True).transition("t", ["go"], ["e"], net_ended("leaf"))
    top = NetBuilder("top").place("go", initial=1, action=run("middle"))
    top.place("e", final=True).transition("t", ["go"], ["e"], net_ended("middle"))
    return [leaf.build(), middle.build(), top.build()]


def test_kill_ends_the_net_and_all_its_sub_nets(tmp_path: Path) -> None:
    rig = rig_with(tmp_path, *nested())
    iid = rig.dispatch.start("top")
    assert sorted(r["net"] for r in rig.dispatch.running()) == ["leaf", "middle", "top"]
    assert rig.dispatch.kill(iid)
    ended = [
        (m.payload["net"], m.payload["outcome"]) for m in rig.log if m.type == "petri_net_ended"
    ]
    assert ended == [("leaf", "killed"), ("middle", "killed"), ("top", "killed")]
    assert rig.dispatch.running() == []
    assert not rig.dispatch.kill(iid)


def test_a_killed_sub_net_is_reported_to_its_parent(tmp_path: Path) -> None:
    rig = rig_with(tmp_path, *nested())
    iid = rig.dispatch.start("top")
    rig.client.publish("kill_petri_net", {"net": "leaf"})
    assert rig.ended(iid) == "done"  # leaf killed -> middle ends -> top ends
    assert rig.dispatch.running() == []


def test_monitoring_events_replay_to_the_live_marking(tmp_path: Path) -> None:
    rig = make_rig()
    iid = rig.dispatch.start("wink_one_eye")
    rig.say("servo_in_position", servo="eyelid_left", position=0.0)
    rig.say("servo_in_position", servo="eyelid_right", position=0.0)
    replayed: dict[str, int] = {}
    for m in rig.log:
        if m.type == "petri_net_event" and m.payload["instance_id"] == iid:
            if m.payload["kind"] == "started":
                replayed = dict(m.payload["marking"])
            else:
                replayed.update(m.payload["marking"])
    instance = rig.dispatch.get(iid)
    assert instance is not None
    assert {k: v for k, v in replayed.items() if v} == instance.marking() == {"wait": 1}


def test_a_step_is_one_monitoring_event_with_its_firings_in_order(tmp_path: Path) -> None:
    b = NetBuilder("steps")
    b.place("p0", initial=2).place("p1").place("p2").place("wait").place("end", final=True)
    b.transition("t0", {"p0": 2}, ["p1", "wait"]).transition("t1", ["p1"], ["p2"])
    b.transition("t2", ["wait", "p2"], ["end"], message("go"))
    rig = rig_with(tmp_path, b.build())
    iid = rig.dispatch.start("steps")
    rig.say("go")
    events = [
        (m.payload["kind"], m.payload.get("transitions"), m.payload["marking"])
        for m in rig.log
        if m.type == "petri_net_event" and m.payload["instance_id"] == iid
    ]
    assert events == [
        ("started", None, {"p0": 2}),
        ("fired", ["t0", "t1"], {"p0": 0, "p1": 0, "wait": 1, "p2": 1}),
        ("fired", ["t2"], {"wait": 0, "p2": 0, "end": 1}),
        ("ended", None, {"end": 1}),
    ]
    fired = [m.payload for m in rig.log if m.type == "petri_net_event"][1]
    assert fired["transition"] == "t1"  # the last of the step, for one-firing monitors
    assert rig.ended(iid) == "done"


def test_without_monitoring_nothing_is_published_but_the_net_runs(tmp_path: Path) -> None:
    rig = rig_with(tmp_path, choice())
    rig.dispatch.monitor = False
    iid = rig.dispatch.start("choice")
    assert [m.type for m in rig.log] == ["petri_net_ended"]
    assert rig.ended(iid) == "done"


def test_a_loop_of_immediate_transitions_yields_and_stays_killable(tmp_path: Path) -> None:
    b = NetBuilder("spin", endless=True)
    b.place("a", initial=1).place("b")
    b.transition("ab", ["a"], ["b"]).transition("ba", ["b"], ["a"])
    rig = rig_with(tmp_path, b.build())
    rig.dispatch.step_budget = 50
    iid = rig.dispatch.start("spin")
    assert len(rig.fired(iid)) == 50
    assert rig.clock.run_ready() == 1  # the engine gave the loop back, then went on
    assert len(rig.fired(iid)) == 100
    assert rig.dispatch.kill(iid)
    assert rig.ended(iid) == "killed"


def test_an_action_error_fails_the_instance_and_says_why(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    b = NetBuilder("broken", params={"point": {}})
    b.place("go", initial=1, final=True, action=publish("navigate_to", {"node": "${point.node}"}))
    rig = rig_with(tmp_path, b.build())
    iid = rig.dispatch.start("broken")
    assert rig.ended(iid) == "failed"
    assert "no 'node' in dict" in caplog.text


def test_guards_choose_by_variables(tmp_path: Path) -> None:
    b = NetBuilder("pick", params={"mode": "fast"})
    b.place("start", initial=1).place("fast", final=True).place("slow", final=True)
    b.transition("is_slow", ["start"], ["slow"], guard("mode", "equals", "slow"))
    b.transition("is_fast", ["start"], ["fast"], guard("mode", "equals", "fast"))
    rig = rig_with(tmp_path, b.build())
    assert rig.fired(rig.dispatch.start("pick")) == ["is_fast"]
    assert rig.fired(rig.dispatch.start("pick", {"mode": "slow"})) == ["is_slow"]


def test_killed_inline_by_a_listener_publishes_nothing_more(tmp_path: Path) -> None:
    b = NetBuilder("two_steps")
    b.place("start", initial=1)
    b.place("first", action=publish("first")).place("second", action=publish("second"))
    b.place("end", final=True)
    b.transition("go", ["start"], ["first", "second"])
    b.transition("both", ["first", "second"], ["end"], message("never"))
    rig = rig_with(tmp_path, b.build())
    rig.client.subscribe(
        "first", lambda m: rig.client.publish("kill_petri_net", {"net": "two_steps"})
    )
    iid = rig.dispatch.start("two_steps")
    assert rig.ended(iid) == "killed"
    assert rig.action_types() == ["first"]


def test_monitors_hear_of_a_firing_before_the_messages_it_causes(tmp_path: Path) -> None:
    b = NetBuilder("causal")
    b.place("p0", initial=1).place("p1").place("said", action=publish("hello"))
    b.place("end", final=True)
    b.transition("t0", ["p0"], ["p1"]).transition("t1", ["p1"], ["said"])
    b.transition("t2", ["said"], ["end"])
    rig = rig_with(tmp_path, b.build())
    rig.dispatch.start("causal")
    seen = [
        m.payload.get("transitions") or m.payload.get("kind") if m.type != "hello" else "hello"
        for m in rig.log
        if m.type in ("petri_net_event", "hello")
    ]
    assert seen == ["started", ["t0", "t1"], "hello", ["t2"], "ended"]
