"""Bookings as a server component (backend.app.COMPONENTS), after the brain and the building
modes: ``app.state.bookings`` (the service the routes use) and its scheduler, which runs where
components run: on the leader only."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from typing import Any
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from fastapi import FastAPI

from backend.bookings.reserve import Reservations
from backend.bookings.schedule import BookingScheduler
from backend.bookings.service import BookingService
from backend.bookings.store import BookingStore
from backend.closure import Closure
from backend.fencing import deciding_endpoint
from backend.state import app_state
from backend.tasks.manager import TaskManager

__all__ = ["bookings", "venue_zone"]


def venue_zone(name: str) -> ZoneInfo:
    """The venue's time zone (``GUIDEBOT_TIMEZONE``); ValueError naming the setting."""
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValueError(
            f"GUIDEBOT_TIMEZONE={name!r} is not a time zone (an IANA name such as Europe/Madrid)"
        ) from None


def _fleet_size(tasks: TaskManager) -> int:
    return sum(1 for r in tasks.robots.values() if not r.out_of_service)


def _duration(tasks: TaskManager) -> Any:
    def duration(kind: str, params: dict[str, Any]) -> float | None:
        try:
            return tasks.estimator.preview(kind, params).duration_s
        except Exception:  # a target the site no longer has: the default length
            return None

    return duration


@contextlib.asynccontextmanager
async def bookings(app: FastAPI) -> AsyncIterator[None]:
    settings = app.state.settings
    tasks: TaskManager = app.state.task_manager
    store = BookingStore(app.state.store.sessionmaker)
    service = BookingService(
        store,
        lambda: app.state.sites.site,
        lambda: _fleet_size(tasks),
        tz=venue_zone(settings.timezone),
        duration=_duration(tasks),
    )
    await service.restore()

    def closures() -> list[Closure]:
        found = app_state(app).closures
        return list(found.closures.values()) if found is not None else []

    def alarm() -> str | None:
        emergency = app_state(app).emergency
        hold = getattr(emergency, "refusal", None)
        return hold(None) if hold is not None else None

    reservations = Reservations(tasks)
    scheduler = BookingScheduler(
        service,
        store,
        tasks,
        app_state(app).alerts,
        closures=closures,
        alarm=alarm,
        check_lead_s=settings.booking_check_lead_s,
        endpoint=deciding_endpoint(app, "bookings"),
        reservations=reservations,
    )
    tasks.reservations = reservations
    service.reserved = lambda key: r.robot if (r := reservations.by_key.get(key)) else None
    tasks.estimator.back_after = reservations.back_after
    async with scheduler:
        app.state.bookings = service
        app.state.booking_scheduler = scheduler
        try:
            yield
        finally:
            tasks.reservations = None
            tasks.estimator.back_after = None
            app.state.bookings = None
            app.state.booking_scheduler = None
