"""The server component of the VDA 5050 master control: on with ``--mqtt`` when the site has
robots with ``interface: vda5050`` (docs/vda5050.md). A published site reaches it without a
restart: the same robots get the new maps, nodes and areas; robots added, removed or renamed
get a new master control, which goes on with the orders the vehicles run."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from typing import Any

from fastapi import FastAPI

from backend.state import app_state
from backend.tasks.manager import NETS
from backend.tasks.targets import net_params
from backend.vda5050.master import MasterControl
from backend.vda5050.pauses import PauseOwner, read_owners
from guidebot.site.schema import Site
from guidebot.vda5050.topics import parse_broker

__all__ = ["vda5050"]

log = logging.getLogger(__name__)


@contextlib.asynccontextmanager
async def vda5050(app: FastAPI) -> AsyncIterator[None]:
    """Run the master control while the server runs; ``app.state.vda5050`` (or None)."""
    settings = app.state.settings
    sites = app.state.sites
    site = sites.site
    app.state.vda5050 = None
    wanted = [r.name for r in site.robots if r.interface == "vda5050"]
    if settings.mqtt_url is None:
        if not wanted:
            yield
            return
        log.warning(
            "VDA 5050 robots %s stay offline: no MQTT broker given (--mqtt mqtt://host:1883)",
            ", ".join(wanted),
        )
        yield
        return
    broker = parse_broker(settings.mqtt_url)
    if settings.mqtt_username is not None:
        broker = type(broker)(
            broker.host,
            broker.port,
            broker.tls,
            settings.mqtt_username,
            settings.mqtt_password or broker.password,
        )
    alerts = app.state.alerts

    def alert(kind: str, subject: str, message: str, lasting: bool) -> None:
        alerts.raise_(kind, subject, message, "error" if lasting else "warning", lasting=lasting)

    def resolve(kind: str, subject: str, why: str) -> None:
        if alerts.is_active(kind, subject):
            alerts.resolve(kind, subject, why)

    tasks = app_state(app).task_manager

    def task_of(robot: str, task_id: str) -> tuple[str, dict[str, Any]] | None:
        """The Task Manager's word on a task a vehicle still runs (after a fail-over)."""
        task = tasks.tasks.get(task_id) if tasks is not None else None
        if task is None or task.final or task.robot != robot:
            return None
        try:
            params = task.assigned_params or net_params(sites.site, task)
        except (KeyError, ValueError, AssertionError) as exc:
            log.warning("VDA 5050: %s's task %s: %s", robot, task_id, exc)
            return None
        return task.net or NETS[task.kind], params

    def holder(area: str) -> str | None:
        traffic = app_state(app).traffic
        if traffic is None or area not in traffic.locks.areas:
            return None
        return traffic.locks.holder(area)  # type: ignore[no-any-return]

    def gate(robot: str, area: str) -> str | None:
        traffic = app_state(app).traffic
        check = getattr(traffic, "gate", None)
        return check(robot, area) if check is not None else None  # type: ignore[no-any-return]

    store = app_state(app).store

    def record(kind: str, data: dict[str, Any]) -> None:
        if store is not None:
            store.record_event(kind, "vda5050", data)

    async def paused_by() -> dict[str, PauseOwner]:
        """Who held each vehicle paused when the last master control stopped (a new leader,
        a restarted server, a new site's master): the event log's word."""
        return {} if store is None else await read_owners(store)

    def make(site: Site, paused: dict[str, PauseOwner]) -> MasterControl:
        return MasterControl(
            site,
            broker,
            app.state.hub.endpoint,
            cafile=settings.mqtt_cafile,
            alert=alert,
            resolve=resolve,
            task_of=task_of,
            holder=holder,
            gate=gate,
            record=record,
            paused_by=paused,
        )

    masters = _Masters(app, make, paused_by)
    await masters.start(site)
    sites.on_change(masters.on_site)
    try:
        yield
    finally:
        await masters.stop()


class _Masters:
    """The master control of the site now (None while it has no VDA 5050 robot)."""

    def __init__(self, app: FastAPI, make: Any, paused_by: Any) -> None:
        self.app, self.make, self.paused_by = app, make, paused_by
        self.master: MasterControl | None = None
        self.stopped = False
        self._lock = asyncio.Lock()

    async def start(self, site: Site) -> None:
        if not MasterControl.identities(site):
            return
        master = self.make(site, await self.paused_by())
        await master.__aenter__()
        self.master = self.app.state.vda5050 = master

    async def on_site(self, site: Site) -> None:
        async with self._lock:
            if self.stopped:
                return
            master = self.master
            identities = MasterControl.identities(site)
            if master is not None and identities == MasterControl.identities(master.site):
                master.use_site(site)
                return
            if master is None and not identities:
                return
            log.info("VDA 5050: the site's VDA 5050 robots changed: a new master control")
            await self._stop()
            await self.start(site)

    async def stop(self) -> None:
        async with self._lock:
            self.stopped = True
            await self._stop()

    async def _stop(self) -> None:
        master, self.master = self.master, None
        self.app.state.vda5050 = None
        if master is not None:
            await master.__aexit__(None, None, None)
