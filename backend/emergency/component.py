"""The EmergencyService as a server component (backend.app.COMPONENTS), after the brain and
the BuildingInterface: it holds the Task Manager (``hold``), the Traffic Manager (``gate``)
and the building (the BuildingInterface asks ``app.state.emergency``)."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from backend.emergency.service import EmergencyService
from backend.fencing import deciding_endpoint
from backend.state import app_state

__all__ = ["emergency"]


@contextlib.asynccontextmanager
async def emergency(app: FastAPI) -> AsyncIterator[None]:
    tasks = app.state.task_manager
    service = EmergencyService(
        deciding_endpoint(app, "emergency"),
        lambda: app.state.sites.site,
        tasks,
        app.state.store,
        lambda: app_state(app).building,
    )
    await service.restore()
    async with service:
        app.state.emergency = service
        tasks.hold = service
        app.state.traffic.gate = service.area_refusal
        try:
            yield
        finally:
            app.state.traffic.gate = None
            tasks.hold = None
            app.state.emergency = None
