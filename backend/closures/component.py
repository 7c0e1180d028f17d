"""The ClosureService as a server component (backend.app.COMPONENTS), after the brain: the
Traffic Manager asks it what is closed (``closures``), and the ETA estimator leaves a queued
tour's closed stops out (``closed``)."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from backend.closures.service import ClosureService
from backend.closures.store import ClosureStore
from backend.fencing import deciding_endpoint

__all__ = ["closures"]


@contextlib.asynccontextmanager
async def closures(app: FastAPI) -> AsyncIterator[None]:
    store = app.state.store
    service = ClosureService(
        deciding_endpoint(app, "closures"),
        lambda: app.state.sites.site,
        ClosureStore(store.sessionmaker),
        store,
        trouble_hold_s=app.state.settings.trouble_hold_s,
    )
    await service.restore()
    traffic = app.state.traffic
    estimator = app.state.task_manager.estimator
    async with service:
        app.state.closures = service
        traffic.closures = lambda: service.closed
        estimator.closed = lambda: service.closed
        try:
            yield
        finally:
            estimator.closed = None
            traffic.closures = None
            app.state.closures = None
