"""The BuildingInterface as a server component (listed in backend.app.COMPONENTS).

Runs after the server brain (it needs ``app.state.sites``), on hub endpoint "building", and
restarts with the new module list whenever the site changes. ``app.state.building`` holds the
running interface (None when the site has no modules or the building is disabled).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from typing import Any

from fastapi import FastAPI

from backend.building.interface import BuildingInterface
from backend.fencing import deciding_endpoint
from backend.health import ComponentState
from backend.site.offloop import off_loop
from guidebot.site.building_config import BUILDING_KEYS, BuildingConfigError, load_building

__all__ = ["building_interface"]

log = logging.getLogger(__name__)


def _node_floors(site: Any) -> dict[str, str]:
    """Node id -> floor: where a building input (a call button) sits."""
    return {node.id: node.floor for node in getattr(site, "nodes", [])}


class _Runner:
    """Holds the current interface; a site change swaps it for one built from the new site."""

    def __init__(self, app: FastAPI) -> None:
        self.app = app
        self.settings = app.state.settings
        self.endpoint = deciding_endpoint(app, "building")
        self.current: BuildingInterface | None = None
        self._lock = asyncio.Lock()
        self._reloads: set[asyncio.Task[None]] = set()

    def _build(self, site: Any, floors: dict[str, str]) -> BuildingInterface | None:
        # Only the building part: a whole 10 000-node site takes tens of ms to dump.
        data = site.model_dump(mode="json", include=set(BUILDING_KEYS))
        config = load_building(data)
        if self.settings.environment != "development":
            config.check_production()
        if not config.modules:
            return None
        return BuildingInterface(
            self.endpoint,
            config,
            filter_ms=getattr(self.settings, "building_filter_ms", 200.0),
            floor_of_node=floors,
        )

    async def load(self, site: Any, *, startup: bool = False) -> None:
        """Start the interface for ``site``; in production a building that cannot run is an
        error (the server refuses to start), in development it is reported on /api/health."""
        health = self.app.state.health
        async with self._lock:
            if self.current is not None:
                await self.current.stop()
                self.current = None
            self.app.state.building = None
            try:
                # Off the loop: on a 10 000-node site the table costs a few ms of GIL time.
                floors = await off_loop(_node_floors, site)
                self.current = self._build(site, floors)
                if self.current is not None:
                    await self.current.start()
            except (BuildingConfigError, OSError) as exc:
                log.error("building interface not started: %s", exc)
                health.set("building_interface", ComponentState.failed, f"not started: {exc}")
                self.current = None
                if startup and self.settings.environment != "development":
                    raise RuntimeError(
                        f"building interface not started: {exc}"
                        f" (GUIDEBOT_ENVIRONMENT={self.settings.environment} refuses to run"
                        " without it)"
                    ) from None
                return
            if self.current is None:
                health.set("building_interface", ComponentState.disabled, "site has no modules")
            else:
                health.set("building_interface", *self.current.component_state())
            self.app.state.building = self.current

    def on_site(self, site: Any) -> None:
        task = asyncio.get_running_loop().create_task(self.load(site))
        self._reloads.add(task)
        task.add_done_callback(self._reloads.discard)

    async def close(self) -> None:
        for task in list(self._reloads):
            task.cancel()
        await asyncio.gather(*self._reloads, return_exceptions=True)
        async with self._lock:
            if self.current is not None:
                await self.current.stop()
                self.current = None
        self.endpoint.close()


@contextlib.asynccontextmanager
async def building_interface(app: FastAPI) -> AsyncIterator[None]:
    """Component: poll the site's Modbus modules while the server runs."""
    app.state.building = None
    if not getattr(app.state.settings, "building_enabled", True):
        app.state.health.set("building_interface", ComponentState.disabled, "building_enabled off")
        yield
        return
    runner = _Runner(app)
    sites = app.state.sites
    await runner.load(sites.site, startup=True)
    sites.on_change(runner.on_site)
    try:
        yield
    finally:
        await runner.close()
        app.state.health.set("building_interface", ComponentState.stopped)
