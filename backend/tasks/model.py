"""Tasks and their life cycle (docs/server.md, "Task life cycle")."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

__all__ = [
    "FINAL_STATES",
    "TRANSITIONS",
    "Held",
    "IllegalTransition",
    "InvalidTask",
    "QueueFull",
    "Task",
    "TaskError",
    "TaskFinished",
    "TaskNotFound",
    "TaskState",
]


class TaskError(ValueError):
    """A task operation refused. The API maps each subclass to one status (docs/server.md,
    "Status codes"): InvalidTask 422, TaskNotFound 404, TaskFinished and IllegalTransition
    409, QueueFull and Held 503."""


class InvalidTask(TaskError):
    """The request names something that does not exist or has bad parameters (422)."""


class TaskNotFound(TaskError, LookupError):
    """No task with that id (404)."""


class TaskFinished(TaskError):
    """The task is done, failed or cancelled: it cannot change any more (409)."""


class QueueFull(TaskError):
    """The queue is at its bound; nothing queued is dropped to make room (503)."""


class Held(TaskError):
    """No new task while the fire alarm holds the site (503, ``reason`` emergency; the text
    in the requester's language: docs/emergency.md)."""

    reason = "emergency"


class IllegalTransition(TaskError):
    """A state change the life cycle does not allow (409)."""


class TaskState(StrEnum):
    QUEUED = "queued"
    ASSIGNED = "assigned"
    """Sent to a robot; not yet confirmed running."""
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"


FINAL_STATES = frozenset({TaskState.DONE, TaskState.FAILED, TaskState.CANCELLED})

TRANSITIONS: dict[TaskState, frozenset[TaskState]] = {
    TaskState.QUEUED: frozenset({TaskState.ASSIGNED, TaskState.CANCELLED}),
    TaskState.ASSIGNED: frozenset(
        {TaskState.RUNNING, TaskState.QUEUED, TaskState.ASSIGNED, *FINAL_STATES}
    ),
    TaskState.RUNNING: frozenset({TaskState.QUEUED, TaskState.ASSIGNED, *FINAL_STATES}),
    TaskState.DONE: frozenset(),
    TaskState.FAILED: frozenset(),
    TaskState.CANCELLED: frozenset(),
}


@dataclass(slots=True)
class Task:
    id: str
    kind: str
    params: dict[str, Any]
    priority: int
    requester: str
    seq: int
    state: TaskState = TaskState.QUEUED
    robot: str | None = None
    pinned_robot: str | None = None
    """Only this robot may take it (reassign to a robot; the idle tasks of a robot)."""
    internal: bool = False
    """Created by the Task Manager itself (charge, go to the wait point): preemptible."""
    net: str = ""
    assigned_params: dict[str, Any] = field(default_factory=dict)
    reason: str = ""
    cancelled_by: str = ""
    """Who cancelled it: "staff", "requester", or "" (not cancelled, or the system); the
    visitor is told "cancelled by staff" (docs/visitor.md). Not kept across a restart."""
    resume_from: int | None = None
    """A tour handed over mid-way: the stop (1-based) the visitor is at, where the next robot
    takes it up (backend/tasks/handover.py); None: from the start. Not kept across a restart."""
    handover: dict[str, Any] | None = None
    """The last handover of a tour: from_robot, stop, total, poi, name, reason, at (Unix
    seconds), arrived_after_s (None until the new robot is at the visitor's stop)."""
    final_progress: dict[str, Any] | None = None
    """A tour that ended on its robot: where it got to (``progress`` of its status, which its
    visitor's page still shows: the stop it ended at, the stops it skipped). Not kept across a
    restart."""
    created_at: float = field(default_factory=time.time)
    updated_at: float = field(default_factory=time.time)
    started_at: float | None = None
    ended_at: float | None = None
    version: int = 0
    """Bumped on every change; the queue uses it to skip stale entries."""

    def move(self, new: TaskState, *, reason: str = "") -> None:
        if new not in TRANSITIONS[self.state]:
            raise IllegalTransition(
                f"task {self.id}: cannot go from {self.state.value} to {new.value} "
                f"(allowed: {sorted(s.value for s in TRANSITIONS[self.state]) or 'none, final'})"
            )
        self.state = new
        self.reason = reason
        self.version += 1
        self.updated_at = time.time()
        if new is TaskState.RUNNING and self.started_at is None:
            self.started_at = self.updated_at
        if new in FINAL_STATES:
            self.ended_at = self.updated_at

    @property
    def final(self) -> bool:
        return self.state in FINAL_STATES

    def handover_view(self) -> dict[str, Any] | None:
        """The last handover as panels, robot screens and staff see it (docs/protocol.md,
        "Handover"): who took the tour up (``robot``), from which robot, at which stop."""
        if self.handover is None:
            return None
        return {k: v for k, v in self.handover.items() if k != "at"} | {"robot": self.robot}

    def as_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "kind": self.kind,
            "params": self.params,
            "priority": self.priority,
            "requester": self.requester,
            "seq": self.seq,
            "state": self.state.value,
            "robot": self.robot,
            "pinned_robot": self.pinned_robot,
            "internal": self.internal,
            "net": self.net,
            "reason": self.reason,
            "cancelled_by": self.cancelled_by,
            "resume_from": self.resume_from,
            "handover": self.handover_view(),
            "created_at": self.created_at,
            "updated_at": self.updated_at,
            "started_at": self.started_at,
            "ended_at": self.ended_at,
        }
