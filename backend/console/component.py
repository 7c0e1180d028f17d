"""The console component (listed in backend.app.COMPONENTS after the server brain)."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from backend.console.alerts import AlertWatcher
from backend.console.feed import ConsoleFeed, relay_events
from backend.console.robocan import RobocanBook
from backend.state import app_state

__all__ = ["console"]


@contextlib.asynccontextmanager
async def console(app: FastAPI) -> AsyncIterator[None]:
    """The feed and the alert watcher (over the brain's ``app.state.alerts``) started;
    ``app.state.console``. Stopped first when the server stops, so the links the server
    closes then raise no alert."""
    store = app.state.store
    endpoint = app.state.hub.endpoint("console")
    watching = app.state.hub.endpoint("alert_watcher")
    watcher = AlertWatcher(watching, app.state.alerts)
    feed = ConsoleFeed(
        endpoint,
        app.state.traffic,
        robots=lambda: {r.name for r in app.state.sites.site.robots},
    )
    listener = relay_events(endpoint)
    store.listeners.append(listener)
    await watcher.start()
    emergency = app_state(app).emergency
    if emergency is not None:  # an alarm kept across a restart was published before this
        watcher.emergency_now(emergency.snapshot())
    await feed.start()
    robocan = RobocanBook(endpoint)
    await robocan.start()
    app.state.console = feed
    app.state.robocan = robocan
    try:
        yield
    finally:
        await robocan.stop()
        await feed.stop()
        await watcher.stop()
        watching.close()
        store.listeners.remove(listener)
        endpoint.close()
