"""The notifier as a server component (backend.app.COMPONENTS, after the console): on a
clustered server it runs on the leader only, and sends only while its lease runs."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from backend.fencing import deciding_endpoint
from backend.notify.service import Notifier
from backend.notify.store import NotifyStore
from backend.state import app_state

__all__ = ["notify"]


@contextlib.asynccontextmanager
async def notify(app: FastAPI) -> AsyncIterator[None]:
    leadership = app_state(app).leadership
    notifier = Notifier(
        deciding_endpoint(app, "notify"),
        NotifyStore(app.state.store.sessionmaker),
        alerts=app.state.alerts,
        may_send=leadership.may_decide if leadership is not None else lambda: True,
    )
    async with notifier:
        app.state.notify = notifier
        try:
            yield
        finally:
            app.state.notify = None
            notifier.endpoint.close()
