"""Breakpoints on a running instance (docs/nets.md, "Attach"): it pauses before the transition,
keeps what arrives meanwhile, steps past it and pauses at the next firing, resumes to its end;
breakpoints that are not renewed go, and the instance goes on by itself."""

from __future__ import annotations

from typing import Any

from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.payloads.petri import PetriNetDebug
from petri_nets.clock import VirtualClock
from petri_nets.dispatch import Dispatch
from petri_nets.library import NetLibrary
from petri_nets.scripted import DEFAULT_REPLIES, ScriptedEnvironment


def rig() -> tuple[Dispatch, VirtualClock, list[Message]]:
    bus = Bus()
    clock = VirtualClock()
    ScriptedEnvironment(bus, clock, DEFAULT_REPLIES)
    dispatch = Dispatch(bus.endpoint("dispatch"), NetLibrary(watch=False), clock, idle_net=None)
    dispatch.open()
    events: list[Message] = []
    bus.endpoint("monitor").subscribe("petri_net_event", events.append, tap=True)
    return dispatch, clock, events


def state(dispatch: Dispatch, instance_id: str) -> dict[str, Any]:
    return next(i for i in dispatch.running() if i["instance_id"] == instance_id)


def test_pause_before_a_transition_step_past_it_and_resume_to_the_end() -> None:
    dispatch, clock, events = rig()
    top = dispatch.start("explain_point", {"text": "Hello"}, instance_id="ep")
    dispatch.debug(
        PetriNetDebug(instance_id=top, command="break", breakpoints=["text_spoken"], lease_s=3600)
    )
    clock.run(until=60.0)
    # speech_ended came (2 s after say): the instance holds before text_spoken fires.
    paused = state(dispatch, top)
    assert paused["paused_at"] == "text_spoken" and paused["breakpoints"] == ["text_spoken"]
    assert paused["marking"].get("synthesize_text") == 1
    said = [e.payload for e in events if e.payload["instance_id"] == top]
    assert said[-1]["kind"] == "paused" and said[-1]["transition"] == "text_spoken"
    # Step: text_spoken fires, and the next firing (once head_talk ends) waits.
    assert dispatch.debug(PetriNetDebug(instance_id=top, command="step"))
    clock.run(until=120.0)
    assert state(dispatch, top)["paused_at"] == "head_talk_finished"
    fired = [
        t
        for e in events
        if e.payload["kind"] == "fired" and e.payload["instance_id"] == top
        for t in e.payload["transitions"]
    ]
    assert fired == ["people_faced", "text_spoken"]
    # Resume: no breakpoint before the others, the net ends.
    assert dispatch.debug(PetriNetDebug(instance_id=top, command="resume"))
    clock.run(until=200.0)
    ended = [e.payload for e in events if e.payload["kind"] == "ended"]
    assert any(p["instance_id"] == top for p in ended)
    assert dispatch.running() == []


def test_breakpoints_not_renewed_go_and_the_instance_goes_on() -> None:
    dispatch, clock, events = rig()
    top = dispatch.start("explain_point", {"text": "Hello"})
    dispatch.debug(
        PetriNetDebug(instance_id=top, command="break", breakpoints=["people_faced"], lease_s=30)
    )
    clock.run(until=20.0)
    assert state(dispatch, top)["paused_at"] == "people_faced"
    dispatch.debug(  # renewed at 20 s: holds until 50 s
        PetriNetDebug(instance_id=top, command="break", breakpoints=["people_faced"], lease_s=30)
    )
    clock.run(until=45.0)
    assert state(dispatch, top)["paused_at"] == "people_faced"
    clock.run(until=300.0)
    assert dispatch.running() == []
    assert any(e.payload["kind"] == "ended" and e.payload["instance_id"] == top for e in events)
    # A step or resume of an instance that is not there is refused.
    assert not dispatch.debug(PetriNetDebug(instance_id=top, command="step"))
