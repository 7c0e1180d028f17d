"""Metrics as a server component (listed in backend.app.COMPONENTS): ``app.state.metrics``."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from backend.metrics.server import ServerMetrics
from backend.state import app_state

__all__ = ["metrics"]


@contextlib.asynccontextmanager
async def metrics(app: FastAPI) -> AsyncIterator[None]:
    """Tap the hub for the server's whole life; services are looked up at scrape time."""
    endpoint = app.state.hub.endpoint("metrics")
    server_metrics = ServerMetrics(app_state(app), endpoint)
    app.state.metrics = server_metrics
    try:
        async with server_metrics:
            yield
    finally:
        endpoint.close()
