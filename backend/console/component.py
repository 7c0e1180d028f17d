"""The console component (listed in backend.app.COMPONENTS after the server brain)."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from backend.console.alerts import AlertBook
from backend.console.feed import ConsoleFeed, relay_events
from backend.console.robocan import RobocanBook

__all__ = ["console"]


@contextlib.asynccontextmanager
async def console(app: FastAPI) -> AsyncIterator[None]:
    """Alerts restored from the event log, the feed started; ``app.state.console``."""
    store = app.state.store
    endpoint = app.state.hub.endpoint("console")
    alerts = AlertBook(store, endpoint.publish)
    await alerts.restore(store.events)
    feed = ConsoleFeed(
        endpoint,
        app.state.traffic,
        alerts,
        robots=lambda: {r.name for r in app.state.sites.site.robots},
    )
    listener = relay_events(endpoint)
    store.listeners.append(listener)
    await feed.start()
    robocan = RobocanBook(endpoint)
    await robocan.start()
    app.state.console = feed
    app.state.alerts = alerts
    app.state.robocan = robocan
    try:
        yield
    finally:
        await robocan.stop()
        await feed.stop()
        store.listeners.remove(listener)
        endpoint.close()
