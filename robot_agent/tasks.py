"""Main tasks on the robot: what the Task Manager assigns, run as RoboGraph nets.

Only one main task runs at a time. While idle the robot runs its waiting net; a main task kills
it and it is restarted when the main task ends. The runner talks to RG dispatch with messages
only (run_petri_net / kill_petri_net / petri_net_ended) and reports task_started / task_ended
to the Task Manager.
"""

from __future__ import annotations

import collections
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Literal

from pydantic import ValidationError

from guidebot.bus import BusEndpoint
from guidebot.messages import Message, make_message
from guidebot.pace import net_params, pace_of
from guidebot.payloads.petri import KillPetriNet, RunPetriNet
from guidebot.payloads.tasks import (
    Outcome,
    TaskAssigned,
    TaskCancel,
    TaskEnded,
    TaskStarted,
    TourProgress,
)
from guidebot.service import Service

__all__ = ["IllegalTransition", "MainTask", "TaskPhase", "TaskRunner"]

log = logging.getLogger(__name__)

OUTCOMES: dict[str, Outcome] = {"done": "done", "killed": "cancelled", "failed": "failed"}
FINISHED_KEPT = 50
"""Ended tasks remembered, to answer a task_assigned resent for one of them."""


class TaskPhase(StrEnum):
    STARTING = "starting"
    RUNNING = "running"
    CANCELLING = "cancelling"
    ENDED = "ended"


TRANSITIONS: dict[TaskPhase, frozenset[TaskPhase]] = {
    TaskPhase.STARTING: frozenset({TaskPhase.RUNNING, TaskPhase.CANCELLING, TaskPhase.ENDED}),
    TaskPhase.RUNNING: frozenset({TaskPhase.CANCELLING, TaskPhase.ENDED}),
    TaskPhase.CANCELLING: frozenset({TaskPhase.ENDED}),
    TaskPhase.ENDED: frozenset(),
}


class IllegalTransition(RuntimeError):
    pass


@dataclass
class MainTask:
    task_id: str
    net: str
    params: dict[str, Any]
    instance_id: str
    phase: TaskPhase = TaskPhase.STARTING
    reason: str = ""
    outcome: Outcome | None = None
    """How it ended (ENDED only)."""
    problem: str = ""
    """The last thing that went wrong while it ran (navigation_failed, a robot fault): the
    reason given when its net fails without saying why."""
    problem_trouble: bool = False
    """``problem`` is a navigation_failed whose way trouble alone cut off (its flag)."""
    trouble: bool = False
    """It failed for ``problem_trouble``'s cause (task_ended's ``trouble``)."""
    history: list[TaskPhase] = field(default_factory=list)
    run_request_id: str = ""
    """The id of the run_petri_net request, to tie RG's refusal (an ``error``) to this task."""
    again: bool = False
    """Cut off by the fire alarm: the server gives it again on resume, so it is run then, not
    answered as already ended (docs/emergency.md)."""

    def move(self, to: TaskPhase) -> None:
        if to not in TRANSITIONS[self.phase]:
            raise IllegalTransition(
                f"task {self.task_id}: {self.phase} -> {to} is illegal; "
                f"expected one of {sorted(TRANSITIONS[self.phase])}"
            )
        self.history.append(self.phase)
        self.phase = to


class TaskRunner(Service):
    """Runs main tasks and the waiting task through RG dispatch."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        robot: str,
        *,
        waiting_net: str | None = "waiting",
        on_cancel: Callable[[], None] | None = None,
        on_start: Callable[[], None] | None = None,
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.waiting_net = waiting_net
        self.on_cancel = on_cancel
        self.on_task_start = on_start
        self.current: MainTask | None = None
        self.finished: collections.deque[MainTask] = collections.deque(maxlen=FINISHED_KEPT)
        """The last tasks that ended: a task_assigned resent for one of them (the server
        restarted, or the link was down when it ended) is answered, not run again."""
        self.running_nets: dict[str, str] = {}
        self._waiting_instance: str | None = None
        self._waiting_seq = 0

    async def on_start(self) -> None:
        self.subscribe_all(
            self.ep,
            {
                "petri_net_ended": self._on_net_ended,
                "petri_net_event": self._on_net_event,
                "show_point": self._on_point,
                "point_explained": self._on_point,
                "point_skipped": self._on_point,
                "navigation_failed": self._on_problem,
                "robot_fault": self._on_problem,
                "error": self._on_refused,
            },
        )
        self.on(self.ep, TaskAssigned, self._on_assigned)
        self.on(self.ep, TaskCancel, self._on_cancel)
        self._start_waiting()

    @property
    def task_id(self) -> str | None:
        return self.current.task_id if self.current else None

    # -- waiting task -------------------------------------------------------------------------

    def _start_waiting(self) -> None:
        if self.waiting_net is None or self._waiting_instance is not None:
            return
        self._waiting_seq += 1
        self._waiting_instance = f"{self.robot}-waiting-{self._waiting_seq}"
        self.running_nets[self._waiting_instance] = self.waiting_net
        self.ep.publish(
            RunPetriNet(net=self.waiting_net, instance_id=self._waiting_instance, main=False),
        )

    def _kill_waiting(self) -> None:
        instance, self._waiting_instance = self._waiting_instance, None
        if instance is not None:
            self.ep.publish(KillPetriNet(instance_id=instance))

    # -- main tasks ---------------------------------------------------------------------------

    def _on_assigned(self, message: Message, assigned: TaskAssigned) -> None:
        if assigned.robot != self.robot:
            return
        task_id, net = assigned.task_id, assigned.net
        if not task_id or not net:
            log.warning("%s: task_assigned without task_id or net: %s", self.robot, assigned)
            return
        ended = next((t for t in self.finished if t.task_id == task_id), None)
        if ended is not None:
            # Resent after a reconnect while its task_ended was still queued: say it again.
            log.info(
                "%s: task %s already ended (%s): not run again", self.robot, task_id, ended.outcome
            )
            self._report_ended(ended)
            return
        if self.current is not None:
            if self.current.task_id == task_id:
                return  # a duplicate after a reconnect: already running
            # The server thinks this robot is free: it forgot the running task (a restart) or
            # missed its end. The server requeues the refused one; ours is reconciled.
            busy = f"robot busy with task {self.current.task_id}"
            self.ep.publish(
                TaskEnded(task_id=task_id, robot=self.robot, outcome="refused", reason=busy)
            )
            return
        given = assigned.params
        # A slower tour gives the visitor longer to answer "continue?"; a task's own values win.
        params = {**net_params(pace_of(given)), **given}
        task = MainTask(task_id, net, params, instance_id=f"{self.robot}-task-{task_id}")
        self.current = task
        self._kill_waiting()
        if self.on_task_start is not None:
            self.on_task_start()
        self.running_nets[task.instance_id] = net
        request = make_message(
            RunPetriNet(net=net, instance_id=task.instance_id, params=task.params, main=True),
            source=self.ep.name,
        )
        task.run_request_id = request.id  # known before RG answers, even inside the send
        self.ep.send(request)
        if task.phase is not TaskPhase.STARTING:
            return  # RG refused it inside the publish: already reported as ended
        task.move(TaskPhase.RUNNING)
        log.info("%s: task %s started (%s)", self.robot, task_id, net)
        self.ep.publish(TaskStarted(task_id=task_id, robot=self.robot))

    def _on_cancel(self, message: Message, cancel: TaskCancel) -> None:
        task = self.current
        task_id = cancel.task_id
        ended = next((t for t in self.finished if t.task_id == task_id), None)
        if ended is not None and (task is None or task.task_id != task_id):
            # The server heard its end and took the task back (a visit waiting in line for a
            # jammed door to work again): giving it to us again is a new run, not a resend.
            self.finished.remove(ended)
            return
        if task is None or task.task_id != task_id or task.phase is not TaskPhase.RUNNING:
            return
        self._cancel(task, cancel.reason or "cancelled")

    def abort(self, reason: str) -> MainTask | None:
        """Kill the running main task's net now (the fire alarm, robot_agent/evacuation.py);
        the server gives the task again later. Returns the task killed."""
        task = self.current
        if task is None or task.phase is not TaskPhase.RUNNING:
            return None
        task.again = True
        self._cancel(task, reason)
        return task

    def _cancel(self, task: MainTask, reason: str) -> None:
        task.reason = reason
        task.move(TaskPhase.CANCELLING)
        self.ep.publish(KillPetriNet(instance_id=task.instance_id))
        if self.on_cancel is not None:
            self.on_cancel()

    def _on_problem(self, message: Message) -> None:
        task = self.current
        if task is None:
            return
        p = message.payload
        if message.type == "navigation_failed":
            what = f"navigation to {p.get('node') or '?'} failed: {p.get('reason') or 'no reason'}"
        else:
            what = f"robot fault {p.get('kind') or '?'}: {p.get('detail') or ''}".rstrip(": ")
        task.problem = what
        task.problem_trouble = message.type == "navigation_failed" and p.get("trouble") is True

    def _on_refused(self, message: Message) -> None:
        """RG's ``error`` for our run request: its reason becomes the task's failure reason."""
        task = self.current
        p = message.payload
        if task is not None and p.get("message_id") == task.run_request_id:
            task.problem = str(p.get("reason") or p.get("code") or "refused by RG")

    def _on_net_event(self, message: Message) -> None:
        p = message.payload
        instance, kind = p.get("instance_id"), p.get("kind")
        if kind == "started" and instance:
            self.running_nets[str(instance)] = str(p.get("net"))
        elif kind == "ended" and instance:
            self.running_nets.pop(str(instance), None)

    def _on_net_ended(self, message: Message) -> None:
        p = message.payload
        instance = str(p.get("instance_id") or "")
        self.running_nets.pop(instance, None)
        if instance == self._waiting_instance:
            # The waiting net ended by itself: start it again while idle.
            self._waiting_instance = None
            if self.current is None:
                self._start_waiting()
            return
        task = self.current
        if task is None or instance != task.instance_id:
            return
        outcome = OUTCOMES.get(str(p.get("outcome")), "failed")
        if task.phase is TaskPhase.CANCELLING:
            outcome = "cancelled"
        if outcome == "failed" and not task.reason:
            # A failed task always says why, for the staff and the visitor who asked for it.
            task.reason = task.problem or f"the {task.net} task net failed (no step said why)"
            task.trouble = task.problem_trouble
        task.move(TaskPhase.ENDED)
        task.outcome = outcome
        self.current = None
        if not task.again:
            self.finished.append(task)
        log.info("%s: task %s %s %s", self.robot, task.task_id, outcome, task.reason)
        self._report_ended(task)
        self._start_waiting()

    def _report_ended(self, task: MainTask) -> None:
        self.ep.publish(
            TaskEnded(
                task_id=task.task_id,
                robot=self.robot,
                outcome=task.outcome or "failed",
                reason=task.reason,
                trouble=task.trouble,
            )
        )

    def _on_point(self, message: Message) -> None:
        """give_tour reached, explained or skipped a point: tour_progress for the Task Manager."""
        point = message.payload.get("point")
        if self.current is None or not isinstance(point, dict):
            return
        index, total = point.get("index"), point.get("total")
        if not isinstance(index, int) or not isinstance(total, int):
            return  # points without their place in the tour (not from the Task Manager)
        stages: dict[str, Literal["arrived", "explained", "skipped"]] = {
            "show_point": "arrived",
            "point_explained": "explained",
            "point_skipped": "skipped",
        }
        reason = message.payload.get("reason")
        try:
            progress = TourProgress(
                task_id=self.current.task_id,
                robot=self.robot,
                index=index,
                total=total,
                poi=point.get("poi"),
                stage=stages[message.type],
                reason=str(reason)[:500] if isinstance(reason, str) else "",
            )
        except ValidationError as exc:  # the Task Manager would refuse it
            log.warning("%s: tour point not reported: %s", self.robot, exc)
            return
        self.ep.publish(progress)
