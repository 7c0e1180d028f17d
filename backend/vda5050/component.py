"""The server component of the VDA 5050 master control: on with ``--mqtt`` when the site has
robots with ``interface: vda5050`` (docs/vda5050.md)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator
from typing import Any

from fastapi import FastAPI

from backend.tasks.manager import NETS
from backend.tasks.targets import net_params
from backend.vda5050.master import MasterControl
from guidebot.vda5050.topics import parse_broker

__all__ = ["vda5050"]

log = logging.getLogger(__name__)


@contextlib.asynccontextmanager
async def vda5050(app: FastAPI) -> AsyncIterator[None]:
    """Run the master control while the server runs; ``app.state.vda5050`` (or None)."""
    settings = app.state.settings
    site = app.state.sites.site
    app.state.vda5050 = None
    wanted = [r.name for r in site.robots if r.interface == "vda5050"]
    if not wanted:
        yield
        return
    if settings.mqtt_url is None:
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

    tasks = getattr(app.state, "task_manager", None)

    def task_of(robot: str, task_id: str) -> tuple[str, dict[str, Any]] | None:
        """The Task Manager's word on a task a vehicle still runs (after a fail-over)."""
        task = tasks.tasks.get(task_id) if tasks is not None else None
        if task is None or task.final or task.robot != robot:
            return None
        try:
            params = task.assigned_params or net_params(site, task)
        except (KeyError, ValueError, AssertionError) as exc:
            log.warning("VDA 5050: %s's task %s: %s", robot, task_id, exc)
            return None
        return task.net or NETS[task.kind], params

    master = MasterControl(
        site,
        broker,
        app.state.hub.endpoint,
        cafile=settings.mqtt_cafile,
        alert=alert,
        resolve=resolve,
        task_of=task_of,
    )
    async with master:
        app.state.vda5050 = master
        yield
