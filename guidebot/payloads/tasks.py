"""Payload models of the tasks messages (registered by type name)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload
from guidebot.task_kinds import TaskKind

__all__ = [
    "ReactionMeasured",
    "RobotLink",
    "RobotService",
    "TaskAssigned",
    "TaskCancel",
    "TaskEnded",
    "TaskEvent",
    "TaskReaction",
    "TaskRequest",
    "TaskStarted",
    "TourProgress",
    "VisitorService",
]

Outcome = Literal["done", "failed", "cancelled", "refused"]
"""refused: the robot did not start it (it runs another task); the Task Manager requeues it."""


@register_payload("task_request")
class TaskRequest(PayloadModel):
    """A visitor, button, robot screen or admin asks for a task; higher priority first."""

    kind: TaskKind
    params: dict[str, Any] = Field(default_factory=dict)
    priority: int = Field(default=5, ge=0, le=100)
    requester: str = Field(default="", max_length=64)


@register_payload("task_assigned")
class TaskAssigned(PayloadModel):
    task_id: str
    robot: str
    net: str
    params: dict[str, Any] = Field(default_factory=dict)
    handover: dict[str, Any] | None = None
    """A tour taken up from another robot: {from_robot, robot, stop, total, poi, name, reason,
    arrived_after_s}; the robot's screen says so (docs/protocol.md, "Handover")."""


@register_payload("task_cancel")
class TaskCancel(PayloadModel):
    task_id: str
    reason: str = ""


@register_payload("task_started")
class TaskStarted(PayloadModel):
    task_id: str
    robot: str


@register_payload("task_ended")
class TaskEnded(PayloadModel):
    task_id: str
    robot: str
    outcome: Outcome = "done"
    reason: str = ""
    trouble: bool = False
    """With outcome failed: the failure is a navigation_failed whose way trouble alone cut
    off (its ``trouble`` flag): the Task Manager queues a visitor's task until the trouble
    lifts, if its map shows it so. An older robot sends none: its failure stands."""


@register_payload("task_reaction")
class TaskReaction(PayloadModel):
    """The robot's side of the reaction chain (docs/reaction.md), sent once per task, when the
    robot first moves for it. Wall-clock stamps (time.time()), seconds."""

    task_id: str
    robot: str
    received_at: float
    """The link got task_assigned (T9)."""
    net_started_at: float | None = None
    """RG dispatch was asked to run the task's net (T10)."""
    path_requested_at: float | None = None
    """Navigation sent get_path."""
    path_received_at: float | None = None
    """The path arrived (T11)."""
    commanded_at: float
    """Navigation published the first non-zero set_velocity (T13)."""
    moving_at: float
    """The base entity had put the first non-zero velocity frame on the CAN bus (T14)."""


@register_payload("reaction_measured")
class ReactionMeasured(PayloadModel):
    """The server's join of one task's reaction chain (docs/reaction.md): every stamp known,
    and each step in milliseconds. ``button`` is set when a building button started it."""

    task_id: str
    robot: str
    button: str | None = None
    stamps: dict[str, float]
    steps_ms: dict[str, float]


@register_payload("task_event")
class TaskEvent(PayloadModel):
    """Every state change of a task, for GUIs, panels and the event log."""

    task_id: str
    state: str
    robot: str | None = None
    queue_position: int | None = None
    eta_s: float | None = None
    """Estimated wait before a robot starts on it (None: no robot can serve it now)."""
    service: str | None = None
    """available | busy | held_up | paused | unavailable | ended | withdrawn (docs/visitor.md,
    "The wait")."""
    arrival_s: float | None = None
    """Estimated seconds until the robot is at the first point."""
    remaining_s: float | None = None
    duration_s: float | None = None
    progress: dict[str, Any] | None = None
    """Tours: {index, total, poi, name, stage: arrived | explained}; ``poi`` and ``name``
    are the point the robot reported (its real place), never an index into the tour. A visit
    to one point: index 1 of 1, arrived, once its robot shows the point."""
    reason: str = ""
    cancelled_by: str = ""
    """Cancelled tasks: "staff", "requester" or "" (the system)."""
    handover: dict[str, Any] | None = None
    """A tour handed over mid-way (docs/protocol.md, "Handover"): {from_robot, robot, stop,
    total, poi, name, reason, arrived_after_s}; ``arrival_s`` is when ``robot`` is at ``stop``."""
    trouble: dict[str, Any] | None = None
    """Queued, waiting for trouble on its way to lift (a jammed door, a stuck lift): {why
    ("door D0 out of order", the form of docs/protocol.md "Skipped stops"), wait (1-based),
    waits (the most before it fails)}; docs/visitor.md, "Waiting for trouble"."""


@register_payload("visitor_service")
class VisitorService(PayloadModel):
    """What a new visitor request would be told changed (the overall service, or the wait
    for the next free robot): the visitor panels read their menu again (docs/visitor.md)."""

    service: str
    """available | busy | held_up | paused | unavailable."""
    eta_s: float | None = None
    """Seconds until the first robot is free after the line (None: not known)."""


@register_payload("tour_progress")
class TourProgress(PayloadModel):
    """A robot reached (arrived), finished explaining (explained) or skipped (skipped: closed
    off, ``reason`` says why) point ``index`` (1-based) of its tour; the Task Manager records
    it and tells the panels."""

    task_id: str = Field(max_length=64)
    robot: str = Field(max_length=64)
    index: int = Field(ge=1, le=10_000)
    total: int = Field(ge=1, le=10_000)
    poi: str | None = Field(default=None, max_length=64)
    stage: Literal["arrived", "explained", "skipped"]
    reason: str = Field(default="", max_length=500)
    """Stage ``skipped``: why (only closed elements lead there: "gallery g2 closed: ...")."""


@register_payload("robot_connected")
@register_payload("robot_disconnected")
class RobotLink(PayloadModel):
    """A robot's hub link came up or dropped (published by the server, not by robots)."""

    robot: str


@register_payload("robot_service")
class RobotService(PayloadModel):
    """Staff took a robot out of service (it gets no task) or put it back (Task Manager)."""

    robot: str
    out_of_service: bool
    by: str = ""
