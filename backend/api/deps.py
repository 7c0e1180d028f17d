"""Shared dependencies of the REST routers: roles as Annotated aliases, services from app.state."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, HTTPException, Request, status

from backend.auth import Principal, Role, require_roles
from backend.db.store import DbStore
from backend.site.service import SiteService
from backend.tasks.manager import TaskManager
from backend.traffic.manager import TrafficManager

__all__ = [
    "Admin",
    "Anyone",
    "Requester",
    "Staff",
    "forbid",
    "not_found",
    "sites",
    "store",
    "task_manager",
    "traffic",
]

Admin = Annotated[Principal, Depends(require_roles(Role.ADMIN))]
Staff = Annotated[Principal, Depends(require_roles(Role.OPERATOR))]
"""Operators (and admins): tasks, locks, robots, events."""
Requester = Annotated[Principal, Depends(require_roles(Role.OPERATOR, Role.PANEL, Role.ROBOT))]
"""Who may request a task and follow it."""
Anyone = Annotated[
    Principal, Depends(require_roles(Role.OPERATOR, Role.PANEL, Role.ROBOT, Role.GUI))
]
"""Any known token: reading tours and points of interest."""


def task_manager(request: Request) -> TaskManager:
    return request.app.state.task_manager  # type: ignore[no-any-return]


def traffic(request: Request) -> TrafficManager:
    return request.app.state.traffic  # type: ignore[no-any-return]


def sites(request: Request) -> SiteService:
    return request.app.state.sites  # type: ignore[no-any-return]


def store(request: Request) -> DbStore:
    return request.app.state.store  # type: ignore[no-any-return]


def not_found(what: str) -> HTTPException:
    return HTTPException(status.HTTP_404_NOT_FOUND, f"{what} not found")


def forbid(reason: str) -> HTTPException:
    return HTTPException(status.HTTP_403_FORBIDDEN, reason)
