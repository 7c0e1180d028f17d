"""Shared dependencies of the REST routers: roles as Annotated aliases, services from app.state
as typed Annotated dependencies (``manager: Tasks``)."""

from __future__ import annotations

from typing import Annotated, Any, TypeVar, cast

from fastapi import Depends, HTTPException, Request, status
from fastapi.routing import APIRoute

from backend.actions import require_action
from backend.auth import Principal, RoleCheck
from backend.db.store import DbStore
from backend.ratelimit import RateLimited
from backend.site.service import SiteService
from backend.tasks.manager import TaskManager
from backend.traffic.manager import TrafficManager

__all__ = [
    "ERRORS",
    "Admin",
    "Anyone",
    "NetKiller",
    "NetReader",
    "PlanPath",
    "Requester",
    "SeeRobot",
    "Sites",
    "Staff",
    "Store",
    "TaskReader",
    "TaskRequester",
    "Tasks",
    "Traffic",
    "Watcher",
    "app_service",
    "error_response",
    "forbid",
    "not_found",
    "rate_limited",
    "require_action",
    "role_check",
    "sites",
    "store",
    "task_manager",
    "traffic",
]

Admin = Annotated[Principal, Depends(require_action("administer"))]
Staff = Annotated[Principal, Depends(require_action("operate"))]
"""Operators (and admins): tasks, locks, robots, events."""
Watcher = Annotated[Principal, Depends(require_action("watch"))]
"""Who may read what the console shows (operators, viewers): its changes are ``Staff``'s."""
TaskReader = Annotated[Principal, Depends(require_action("read_tasks"))]
"""Who may read tasks (``Requester``'s own-only terms) without cancelling them: viewers too."""
Requester = Annotated[Principal, Depends(require_action("follow_tasks"))]
"""Who may follow (and cancel) the tasks it requested: staff see them all."""
TaskRequester = Annotated[Principal, Depends(require_action("task_request"))]
"""Who may request a task: the same rule as the hub's ``task_request``."""
SeeRobot = Annotated[Principal, Depends(require_action("see_robot"))]
PlanPath = Annotated[Principal, Depends(require_action("plan_path"))]
NetKiller = Annotated[Principal, Depends(require_action("kill_petri_net"))]
NetReader = Annotated[Principal, Depends(require_action("read_nets"))]
"""Who may read the nets library and running nets: the console and the net editor's readers."""
"""Who may stop a running net: the same rule as the hub's ``kill_petri_net``."""
Anyone = Annotated[Principal, Depends(require_action("read"))]
"""Any known token: reading tours and points of interest."""


ServiceT = TypeVar("ServiceT")


def app_service(request: Request, name: str, kind: type[ServiceT]) -> ServiceT:
    """A service the app factory's components put on app.state, checked for its type."""
    value = getattr(request.app.state, name, None)
    if not isinstance(value, kind):
        raise RuntimeError(f"app.state.{name} is not a {kind.__name__}: is its component started?")
    return value


def task_manager(request: Request) -> TaskManager:
    return app_service(request, "task_manager", TaskManager)


def traffic(request: Request) -> TrafficManager:
    return app_service(request, "traffic", TrafficManager)


def sites(request: Request) -> SiteService:
    return app_service(request, "sites", SiteService)


def store(request: Request) -> DbStore:
    return app_service(request, "store", DbStore)


Tasks = Annotated[TaskManager, Depends(task_manager)]
"""The Task Manager, as a route parameter (``manager: Tasks``)."""
Traffic = Annotated[TrafficManager, Depends(traffic)]
Sites = Annotated[SiteService, Depends(sites)]
Store = Annotated[DbStore, Depends(store)]


def role_check(route: APIRoute) -> RoleCheck | None:
    """The token check among a route's dependencies; None for a public route."""
    pending = list(route.dependant.dependencies)
    while pending:
        dependant = pending.pop()
        if hasattr(dependant.call, "roles") and hasattr(dependant.call, "action"):
            return cast(RoleCheck, dependant.call)
        pending.extend(dependant.dependencies)
    return None


def not_found(what: str) -> HTTPException:
    return HTTPException(status.HTTP_404_NOT_FOUND, f"{what} not found")


def forbid(reason: str) -> HTTPException:
    return HTTPException(status.HTTP_403_FORBIDDEN, reason)


def rate_limited(exc: RateLimited) -> HTTPException:
    """429 with a sentence a visitor panel can show, and Retry-After."""
    return HTTPException(
        status.HTTP_429_TOO_MANY_REQUESTS, str(exc), headers={"Retry-After": str(exc.retry_after)}
    )


def error_response(description: str) -> dict[str, Any]:
    """An error status's OpenAPI entry: ``{"detail": ...}`` with what it means."""
    return {
        "description": description,
        "content": {
            "application/json": {
                "schema": {"type": "object", "properties": {"detail": {}}, "required": ["detail"]}
            }
        },
    }


ERRORS: dict[int | str, dict[str, Any]] = {
    401: error_response("missing or unknown bearer token"),
    403: error_response("the token's role may not do this"),
    404: error_response("no such id in the path (or not yours to see)"),
    409: error_response("the thing cannot change any more (a finished task)"),
    413: error_response("request body too large"),
    422: error_response("bad input: each problem with its place"),
    429: error_response("too many requests or failed sign-ins; Retry-After says when to try again"),
    503: error_response(
        "the task queue is full; or, with several server processes, this one is not the leader"
    ),
}
"""Every error status the API answers, documented on every route (docs/server.md)."""
