"""The BuildingInterface as a server component (listed in backend.app.COMPONENTS).

Runs after the server brain (it needs ``app.state.sites``), on hub endpoint "building", and
restarts with the new module list when the site's building part changes (other edits leave it
running: a restart reconnects every module and forgets who holds which door open).
``app.state.building`` holds the running interface (None when the site has no modules or the
building is disabled).
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
from backend.state import app_state
from guidebot.site.building_config import BUILDING_KEYS, BuildingConfigError, load_building

__all__ = ["building_interface"]

log = logging.getLogger(__name__)


def _node_floors(site: Any) -> dict[str, str]:
    """Node id -> floor: where a building input (a call button) sits."""
    return {node.id: node.floor for node in getattr(site, "nodes", [])}


Part = tuple[dict[str, Any], dict[str, str], tuple[tuple[str, str, int], ...]]


def _building_part(site: Any, floors: dict[str, str]) -> Part:
    """What the interface is built from: the site's building sections, the floor of each node
    that one of their points names, and the fire alarm's inputs (read on their own, faster).
    Two sites with the same part run the same interface."""
    data = site.model_dump(mode="json", include=set(BUILDING_KEYS))
    named = {
        point["node"]
        for module in data.get("modules") or []
        for point in module.get("points") or []
        if point.get("node") is not None
    }
    emergency = getattr(site, "emergency", None)
    alarms = tuple(
        sorted(
            {(a.input.module, a.input.point, a.active_when) for a in emergency.alarms}
            if emergency
            else ()
        )
    )
    return data, {node: floors[node] for node in sorted(named) if node in floors}, alarms


class _Runner:
    """Holds the current interface; a site change swaps it for one built from the new site."""

    def __init__(self, app: FastAPI) -> None:
        self.app = app
        self.settings = app.state.settings
        self.endpoint = deciding_endpoint(app, "building")
        self.current: BuildingInterface | None = None
        self._lock = asyncio.Lock()
        self._reloads: set[asyncio.Task[None]] = set()
        self._part: Part | None = None
        """The building part the current interface was built from."""

    def _build(
        self,
        data: dict[str, Any],
        floors: dict[str, str],
        alarms: tuple[tuple[str, str, int], ...],
    ) -> BuildingInterface | None:
        config = load_building(data)
        if self.settings.environment != "development":
            config.check_production()
        if not config.modules:
            return None
        interface = BuildingInterface(
            self.endpoint,
            config,
            filter_ms=getattr(self.settings, "building_filter_ms", 200.0),
            floor_of_node=floors,
            alarm_inputs={(module, point): value for module, point, value in alarms},
        )
        interface.gate = self._gate
        return interface

    def _gate(self, node: str) -> str | None:
        """The fire alarm's refusal for a device at ``node`` (backend.emergency), if any."""
        emergency = app_state(self.app).emergency
        return None if emergency is None else emergency.building_refusal(node)

    async def load(self, site: Any, *, startup: bool = False) -> None:
        """Start the interface for ``site``; in production a building that cannot run is an
        error (the server refuses to start), in development it is reported on /api/health."""
        health = self.app.state.health
        async with self._lock:
            # Off the loop: on a 10 000-node site the table costs a few ms of GIL time. Only
            # the building part is dumped (the whole site takes tens of ms).
            floors = await off_loop(_node_floors, site)
            part = _building_part(site, floors)
            if self.current is not None and part == self._part:
                # Nothing the building runs on changed (a tour, a label, a node moved): the
                # interface goes on as it is. Restarting it would drop every module's
                # connection and forget which robots hold which doors open.
                return
            if self.current is not None:
                await self.current.stop()
                self.current = None
            self.app.state.building = None
            self._part = None
            try:
                self.current = self._build(*part)
                self._part = part
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
