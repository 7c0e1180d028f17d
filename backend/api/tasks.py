"""Task routes: request, follow, list, cancel, re-prioritise, reassign."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Body, HTTPException, Path, Query, Request, status
from pydantic import BaseModel, ConfigDict, Field

from backend.api.deps import Requester, Staff, forbid, not_found, store, task_manager
from backend.auth import Principal, Role
from backend.tasks.model import Task, TaskError, TaskNotFound, TaskState

__all__ = ["router"]

router = APIRouter(prefix="/api/tasks", tags=["tasks"])

TaskId = Annotated[str, Path(max_length=64)]
PANEL_KINDS = frozenset({"tour", "go_to_poi"})
PANEL_MAX_PRIORITY = 5


class TaskCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: Literal["tour", "go_to_poi", "charge", "go_to"]
    params: dict[str, Any] = Field(default_factory=dict)
    priority: int = Field(default=5, ge=0, le=100)
    robot: str | None = Field(default=None, max_length=64)
    """Staff only: the robot that must do it."""


class Cancel(BaseModel):
    model_config = ConfigDict(extra="forbid")
    reason: str = Field(default="cancelled", max_length=200)


class Reassign(BaseModel):
    model_config = ConfigDict(extra="forbid")
    robot: str | None = Field(default=None, max_length=64)
    """None: the next free robot other than the current one."""


class Priority(BaseModel):
    model_config = ConfigDict(extra="forbid")
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
    """available | busy | unavailable | ended | withdrawn (docs/visitor.md, "The wait")."""
    arrival_s: float | None
    """Estimated seconds until the robot is at the first point."""
    remaining_s: float | None
    duration_s: float | None
    """The task's own length from its first point."""
    progress: dict[str, Any] | None
    """Tours on their robot: {index, total, poi, stage: arrived | explained}."""


def _conflict(exc: TaskError) -> HTTPException:
    if isinstance(exc, TaskNotFound):
        return not_found("task")
    return HTTPException(status.HTTP_409_CONFLICT, str(exc))


def _status(request: Request, task: Task) -> TaskStatus:
    return TaskStatus.model_validate(task_manager(request).status(task))


async def _find(request: Request, task_id: str) -> Task:
    try:
        return task_manager(request).get(task_id)
    except TaskNotFound:
        old = await store(request).task(task_id)
        if old is None:
            raise not_found(f"task {task_id!r}") from None
        return old


def _may_see(who: Principal, task: Task) -> bool:
    if who.role is Role.PANEL:
        return task.requester == who.name
    if who.role is Role.ROBOT:
        return task.robot == who.name or task.requester == who.name
    return True


@router.post("", status_code=status.HTTP_201_CREATED)
async def create_task(
    request: Request, who: Requester, body: Annotated[TaskCreate, Body()]
) -> TaskStatus:
    """Request a task. Panels: tours and points of interest, priority up to 5. Robots: a
    visitor at the robot's screen, so that robot takes it."""
    robot = body.robot
    if who.role is Role.PANEL:
        if body.kind not in PANEL_KINDS or body.robot is not None:
            raise forbid("panels may request tours and points of interest only")
        if body.priority > PANEL_MAX_PRIORITY:
            raise forbid(f"panels may not ask for priority above {PANEL_MAX_PRIORITY}")
    if who.role is Role.ROBOT:
        if body.robot not in (None, who.name):
            raise forbid("a robot may request tasks only for itself")
        robot = who.name
    try:
        task = task_manager(request).request(
            body.kind, body.params, priority=body.priority, requester=who.name, robot=robot
        )
    except TaskError as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None
    return _status(request, task)


@router.get("")
async def list_tasks(
    request: Request,
    _: Staff,
    state: TaskState | None = None,
    robot: Annotated[str | None, Query(max_length=64)] = None,
    include_internal: bool = True,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
) -> dict[str, Any]:
    """Live tasks (queued first, in service order) and recently finished ones."""
    manager = task_manager(request)
    queued = list(manager.queue.ordered())
    others = sorted(
        (t for t in manager.tasks.values() if t.state is not TaskState.QUEUED),
        key=lambda t: -t.updated_at,
    )
    selected = [
        t
        for t in (*queued, *others)
        if (state is None or t.state is state)
        and (robot is None or t.robot == robot)
        and (include_internal or not t.internal)
    ]
    page = selected[offset : offset + limit]
    return {"total": len(selected), "tasks": [_status(request, t) for t in page]}


@router.get("/{task_id}")
async def get_task(request: Request, who: Requester, task_id: TaskId) -> TaskStatus:
    """A task's state, its robot, its queue position and estimated wait."""
    task = await _find(request, task_id)
    if not _may_see(who, task):
        raise not_found(f"task {task_id!r}")
    return _status(request, task)


@router.get("/{task_id}/history")
async def task_history(request: Request, _: Staff, task_id: TaskId) -> list[dict[str, Any]]:
    await _find(request, task_id)
    return await store(request).history(task_id)


@router.post("/{task_id}/cancel")
async def cancel_task(
    request: Request,
    who: Requester,
    task_id: TaskId,
    body: Annotated[Cancel | None, Body()] = None,
) -> TaskStatus:
    """Staff cancel any task; a panel or robot only what it requested."""
    task = await _find(request, task_id)
    if who.role in (Role.PANEL, Role.ROBOT) and task.requester != who.name:
        raise forbid("you may cancel only the tasks you requested")
    try:
        task = task_manager(request).cancel(task_id, reason=(body or Cancel()).reason, by=who.name)
    except TaskError as exc:
        raise _conflict(exc) from None
    return _status(request, task)


@router.post("/{task_id}/reassign")
async def reassign_task(
    request: Request, who: Staff, task_id: TaskId, body: Annotated[Reassign, Body()]
) -> TaskStatus:
    """Move a task to another robot (or back to the queue), even off a broken-down robot."""
    await _find(request, task_id)
    try:
        task = task_manager(request).reassign(task_id, body.robot, by=who.name)
    except TaskError as exc:
        raise _conflict(exc) from None
    return _status(request, task)


@router.post("/{task_id}/priority")
async def reprioritise_task(
    request: Request, _: Staff, task_id: TaskId, body: Annotated[Priority, Body()]
) -> TaskStatus:
    await _find(request, task_id)
    try:
        task = task_manager(request).reprioritise(task_id, body.priority)
    except TaskError as exc:
        raise _conflict(exc) from None
    return _status(request, task)
