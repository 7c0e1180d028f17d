"""The ClosureService as a server component (backend.app.COMPONENTS), after the brain: the
Traffic Manager asks it what is closed (``closures``)."""

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
    )
    await service.restore()
    traffic = app.state.traffic
    async with service:
        app.state.closures = service
        traffic.closures = lambda: service.closed
        try:
            yield
        finally:
            traffic.closures = None
            app.state.closures = None
