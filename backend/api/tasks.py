"""Task routes: request, follow, list, cancel, re-prioritise, reassign.

Status codes (docs/server.md, "Status codes"): a body naming something that does not exist or
with bad parameters 422; an unknown task id in the path 404; a change a finished task cannot
take 409; too many requests 429; the queue at its bound 503.
"""

from __future__ import annotations

import logging
from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, Query, Request, status
from pydantic import BaseModel, Field, model_validator

from backend.actions import TASK_RATE_LIMITED, task_request_refusal
from backend.api.visitor import Me, MeReading, MeRequesting
from backend.auth import Principal, Role
from backend.db.store import DbStore
from backend.ratelimit import RateLimited
from backend.rest.deps import (
    Requester,
    Staff,
    Store,
    TaskReader,
    TaskRequester,
    Tasks,
    Watcher,
    forbid,
    not_found,
    rate_limited,
)
from backend.rest.models import RequestBody
from backend.tasks.manager import TaskManager
from backend.tasks.model import (
    FINAL_STATES,
    InvalidTask,
    Task,
    TaskFinished,
    TaskNotFound,
    TaskState,
)
from backend.tasks.params import validate_params
from guidebot.task_kinds import TaskKind

__all__ = ["router"]

log = logging.getLogger(__name__)
router = APIRouter(prefix="/api/tasks", tags=["tasks"])

TaskId = Annotated[str, Path(max_length=64)]


class TaskCreate(RequestBody):
    kind: TaskKind
    params: dict[str, Any] = Field(default_factory=dict)
    """tour: {tour}; go_to_poi: {poi}; charge: {station} (optional); go_to: {node}."""
    priority: int = Field(default=5, ge=0, le=100)
    robot: str | None = Field(default=None, max_length=64)
    """Staff only: the robot that must do it."""

    @model_validator(mode="after")
    def _strict_params(self) -> TaskCreate:
        try:
            self.params = validate_params(self.kind, self.params)
        except InvalidTask as exc:
            raise ValueError(str(exc)) from None
        return self


class Cancel(RequestBody):
    reason: str = Field(default="cancelled", max_length=200)


class Reassign(RequestBody):
    robot: str | None = Field(default=None, max_length=64)
    """None: the next free robot other than the current one."""


class Priority(RequestBody):
    priority: int = Field(ge=0, le=100)


class TaskStatus(BaseModel):
    id: str
    kind: str
    params: dict[str, Any]
    priority: int
    requester: str
    state: str
    robot: str | None
    pinned_robot: str | None
    internal: bool
    net: str
    reason: str
    created_at: float
    updated_at: float
    started_at: float | None
    ended_at: float | None
    queue_position: int | None
    """1 = next to be served; None unless queued."""
    eta_s: float | None
    """Estimated wait before a robot starts on it (None: no robot can serve it now)."""
    service: str
    """available | busy | held_up | unavailable | ended | withdrawn (docs/visitor.md,
    "The wait")."""
    arrival_s: float | None
    """Estimated seconds until the robot is at the first point."""
    remaining_s: float | None
    duration_s: float | None
    """The task's own length from its first point."""
    progress: dict[str, Any] | None
    """Tours on their robot: {index, total, poi, name, stage: arrived | explained, skipped}:
    the point the robot reported, by id and by name in the task's language, and the stops
    skipped; a finished tour keeps its last (none after a restart)."""
    cancelled_by: str = ""
    """Cancelled tasks: "staff", "requester" or "" (the system; not kept across a restart)."""
    handover: dict[str, Any] | None = None
    """A tour taken up from another robot mid-way (docs/protocol.md, "Handover")."""


class TaskPage(BaseModel):
    total: int
    """Tasks matching the filters, over every page."""
    tasks: list[TaskStatus]


def _status(manager: TaskManager, task: Task) -> TaskStatus:
    return TaskStatus.model_validate(manager.status(task))


async def _find(
    manager: TaskManager, db: DbStore, who: Principal, task_id: str, me: str | None = None
) -> Task:
    """The live task, else the stored one; 404 also for a task this caller may not see
    (``me``: the requester the caller acts as, a panel's device)."""
    try:
        task = manager.get(task_id)
    except TaskNotFound:
        old = await db.task(task_id)
        if old is None:
            raise not_found(f"task {task_id!r}") from None
        task = old
    if not _may_see(who, task, me):
        raise not_found(f"task {task_id!r}")
    return task


def _may_see(who: Principal, task: Task, me: str | None = None) -> bool:
    """Panels (or their devices) see what they requested; robots that and what they run;
    staff everything."""
    if who.role is Role.PANEL:
        return task.requester == (me or who.name)
    if who.role is Role.ROBOT:
        return task.robot == who.name or task.requester == who.name
    return True


def _refuse_finished(task: Task) -> None:
    """A finished task (live or only in the database since a restart) answers 409 the same."""
    if task.state in FINAL_STATES:
        raise TaskFinished(f"task {task.id} is already {task.state.value}")


@router.post("", status_code=status.HTTP_201_CREATED)
async def create_task(
    request: Request,
    who: TaskRequester,
    me: MeRequesting,
    manager: Tasks,
    body: Annotated[TaskCreate, Body()],
) -> TaskStatus:
    """Request a task. Panels: tours and points of interest, priority up to 5 (with a device
    id, the device is the requester). Robots: a visitor at the robot's screen, so that robot
    takes it. Panels and robots are rate-limited per token (429): a panel's devices share
    its limit."""
    refusal = task_request_refusal(
        who.role, who.name, kind=body.kind, priority=body.priority, robot=body.robot
    )
    if refusal is not None:
        raise forbid(refusal)
    robot = who.name if who.role is Role.ROBOT else body.robot
    if who.role in TASK_RATE_LIMITED:
        try:
            request.app.state.task_limits.spend(who.name, f"too many task requests from {who.name}")
        except RateLimited as exc:
            raise rate_limited(exc) from None
    task = manager.request(
        body.kind, body.params, priority=body.priority, requester=me, robot=robot
    )
    # Acknowledge only what the database holds: what a restart after a crash, or a new leader
    # (docs/scaling.md), finds. A database that cannot take it now still gets it later: the
    # store keeps the row pending, so the answer does not wait for ever.
    await _written(request.app.state.store, task.id)
    return _status(manager, task)


async def _written(store: DbStore, task_id: str) -> None:
    try:
        await store.flush()
    except Exception as exc:
        log.warning("task %s answered before it was written: %r", task_id, exc)


@router.get("")
async def list_tasks(
    who: TaskReader,
    me: MeReading,
    manager: Tasks,
    db: Store,
    state: TaskState | None = None,
    robot: Annotated[str | None, Query(max_length=64)] = None,
    include_internal: bool = True,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
) -> TaskPage:
    """Queued tasks first (in service order), then every other task, live or finished, newest
    change first; finished ones survive restarts. Panels and robots see only their own."""
    owner: tuple[str | None, str | None] | None = None
    if who.role is Role.PANEL:
        owner = (me, None)
    elif who.role is Role.ROBOT:
        owner = (who.name, who.name)
    queued: list[Task] = []
    if state in (None, TaskState.QUEUED):
        queued = [
            t
            for t in manager.queue.ordered()
            if (robot is None or t.robot == robot)
            and (include_internal or not t.internal)
            and _may_see(who, t, me)
        ]
    page = queued[offset : offset + limit]
    rest_offset = max(0, offset - len(queued))
    rest_limit = limit - len(page)
    total = len(queued)
    if state is not TaskState.QUEUED:
        counted, stored = await db.list_tasks(
            states=[state.value] if state is not None else None,
            exclude_states=[TaskState.QUEUED.value],
            robot=robot,
            include_internal=include_internal,
            owner=owner,
            offset=rest_offset,
            limit=max(rest_limit, 1),
        )
        total += counted
        if rest_limit > 0:
            live = manager.tasks
            page += [live.get(t.id, t) for t in stored]
    return TaskPage(total=total, tasks=[_status(manager, t) for t in page])


@router.get("/{task_id}")
async def get_task(
    who: TaskReader, me: MeReading, manager: Tasks, db: Store, task_id: TaskId
) -> TaskStatus:
    """A task's state, its robot, its queue position and estimated wait."""
    return _status(manager, await _find(manager, db, who, task_id, me))


@router.get("/{task_id}/history")
async def task_history(
    who: Watcher, manager: Tasks, db: Store, task_id: TaskId
) -> list[dict[str, Any]]:
    await _find(manager, db, who, task_id)
    return await db.history(task_id)


@router.post("/{task_id}/cancel")
async def cancel_task(
    who: Requester,
    me: Me,
    manager: Tasks,
    db: Store,
    task_id: TaskId,
    body: Annotated[Cancel | None, Body()] = None,
) -> TaskStatus:
    """Staff cancel any task; a panel (or a panel's device) or robot only what it requested.
    The task_event says who: ``cancelled_by`` "staff" or "requester"."""
    task = await _find(manager, db, who, task_id, me)
    staff = who.role not in (Role.PANEL, Role.ROBOT)
    if not staff and task.requester != me:
        raise forbid("you may cancel only the tasks you requested")
    _refuse_finished(task)
    reason = (body or Cancel()).reason
    role = "staff" if staff else "requester"
    task = manager.cancel(task_id, reason=reason, by=who.name, by_role=role)
    return _status(manager, task)


@router.post("/{task_id}/reassign")
async def reassign_task(
    who: Staff, manager: Tasks, db: Store, task_id: TaskId, body: Annotated[Reassign, Body()]
) -> TaskStatus:
    """Move a task to another robot (or back to the queue), even off a broken-down robot."""
    _refuse_finished(await _find(manager, db, who, task_id))
    task = manager.reassign(task_id, body.robot, by=who.name)
    return _status(manager, task)


@router.post("/{task_id}/priority")
async def reprioritise_task(
    who: Staff, manager: Tasks, db: Store, task_id: TaskId, body: Annotated[Priority, Body()]
) -> TaskStatus:
    _refuse_finished(await _find(manager, db, who, task_id))
    task = manager.reprioritise(task_id, body.priority)
    return _status(manager, task)
