"""Payload models of the petri messages and the on-board actions nets use (docs/messages.md)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload

__all__ = [
    "AskContinue",
    "ContinueAnswer",
    "KillPetriNet",
    "MoveServos",
    "PetriNetDebug",
    "PetriNetEnded",
    "PetriNetEvent",
    "RunPetriNet",
    "ServoInPosition",
]


@register_payload("run_petri_net")
class RunPetriNet(PayloadModel):
    """Start a net of the library; ``main`` tasks run one at a time per robot."""

    net: str = Field(min_length=1, max_length=64)
    instance_id: str | None = Field(default=None, max_length=64)
    params: dict[str, Any] = Field(default_factory=dict)
    main: bool = False


@register_payload("kill_petri_net")
class KillPetriNet(PayloadModel):
    """Kill one instance (by id) or every instance of a net (by name), with their sub-nets."""

    instance_id: str | None = None
    net: str | None = None


@register_payload("petri_net_ended")
class PetriNetEnded(PayloadModel):
    net: str
    instance_id: str
    outcome: Literal["done", "killed", "failed", "stuck"]
    parent: str | None = None


@register_payload("petri_net_event")
class PetriNetEvent(PayloadModel):
    """Monitoring: "started" carries the whole marking; "fired" the firings of one step in
    order (``transitions``; ``transition`` is the last) and the new counts of the places they
    changed; "paused": a breakpoint holds the instance before ``transition`` (whole marking)."""

    instance_id: str
    net: str
    kind: Literal["started", "fired", "paused", "ended"]
    transition: str | None = None
    transitions: list[str] = Field(default_factory=list)
    marking: dict[str, int] = Field(default_factory=dict)
    time: float


@register_payload("petri_net_debug")
class PetriNetDebug(PayloadModel):
    """A debugger attached to a running instance (docs/nets.md, "Attach"): ``break`` sets its
    breakpoints (transition ids; [] clears them and lets it go on) for ``lease_s`` seconds of
    the dispatch's clock, renewed by the next ``break`` (a page that closes stops renewing:
    its breakpoints go); ``step`` fires the transition it is paused before and pauses before
    the next firing; ``resume`` fires it and runs to the next breakpoint."""

    instance_id: str = Field(min_length=1, max_length=200)
    command: Literal["break", "step", "resume"]
    breakpoints: list[str] = Field(default_factory=list, max_length=1000)
    lease_s: float = Field(default=30.0, gt=0, le=3600)


@register_payload("move_servos")
class MoveServos(PayloadModel):
    servos: dict[str, float]
    speed: float = 1.0


@register_payload("servo_in_position")
class ServoInPosition(PayloadModel):
    servo: str
    position: float
    degraded: bool = False


@register_payload("say")
class Say(PayloadModel):
    text: str
    lang: str = "en"


@register_payload("speech_started")
class SpeechStarted(PayloadModel):
    text: str = ""
    lang: str = "en"
    voice: str | None = None
    """The espeak-ng voice; None when the speech is only timed (no engine, or no voice)."""


@register_payload("speech_ended")
class SpeechEnded(SpeechStarted):
    outcome: Literal["done", "interrupted"] | None = None


@register_payload("face_people")
class FacePeople(PayloadModel):
    pass


@register_payload("people_faced")
class PeopleFaced(PayloadModel):
    pass


@register_payload("navigate_to")
class NavigateTo(PayloadModel):
    node: str
    trouble_wait_s: float | None = None
    """A tour's stop: wait this long for trouble alone cutting it off to lift (robot_agent/
    navigation.py)."""


@register_payload("goal_reached")
class GoalReached(PayloadModel):
    node: str


@register_payload("navigation_failed")
class NavigationFailed(PayloadModel):
    """A goal was not reached (robot_agent.motion.NavigationError says why)."""

    node: str | None
    """The goal's node; None when navigate_to or dock named none the robot could use."""
    reason: str = ""
    closed: bool = False
    """Only closed elements lead there (building modes or trouble, the server's ``path``
    answer): a tour skips the stop and says ``reason`` to its visitor."""
    trouble: bool = False
    """With ``closed``: every closure that cuts the way off is trouble, none by staff (the
    ``path`` answer's ``trouble`` flag). The robot's task_ended carries it to the Task Manager,
    which queues a visitor's task cut off by trouble alone until it lifts; ``reason`` is words
    for people, never parsed."""


@register_payload("ask_continue")
class AskContinue(PayloadModel):
    question: str
    timeout_s: float = 20.0


@register_payload("continue_answer")
class ContinueAnswer(PayloadModel):
    answer: Literal["yes", "no", "timeout"]


@register_payload("show_point")
class ShowPoint(PayloadModel):
    poi: str
    text: str = ""
    media: str | None = None


@register_payload("point_skipped")
class PointSkipped(PayloadModel):
    """give_tour skipped a point only closed elements lead to (the robot's TaskRunner tells
    the Task Manager: tour_progress stage ``skipped``)."""

    point: dict[str, Any]
    reason: str = ""


@register_payload("dock")
class Dock(PayloadModel):
    station: str


@register_payload("docked")
class Docked(PayloadModel):
    station: str | None = None
    node: str | None = None


@register_payload("charged")
class Charged(PayloadModel):
    station: str | None = None
    level: float | None = None
