"""The server brain as one app component: database, site, Task Manager, Traffic Manager,
event log, building buttons and robot tokens. Listed in backend.app.COMPONENTS."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from typing import Any

from fastapi import FastAPI

from backend.auth import Role, TokenStore
from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.site.schema import Site
from backend.site.service import EMPTY_SITE, SiteService
from backend.site.validate import validate_site
from backend.site.yamlio import load_site_file
from backend.tasks.buttons import ButtonWatcher
from backend.tasks.manager import TaskManager
from backend.traffic.graph import SiteGraph
from backend.traffic.manager import TrafficManager
from guidebot.messages import Message

__all__ = ["LOGGED_TYPES", "server_brain"]

log = logging.getLogger(__name__)

LOGGED_TYPES = (
    "battery_low",
    "battery_panic",
    "robot_fault",
    "area_yield",
    "robot_connected",
    "robot_disconnected",
)
"""Hub messages copied into the event log (task changes and lock changes are logged directly)."""


async def _initial_site(app: FastAPI, store: DbStore) -> tuple[Site, int]:
    """The database wins; a site file is imported only into an empty database."""
    stored = await store.load_site()
    if stored is not None:
        version, data = stored
        return validate_site(data), version
    path = getattr(app.state.settings, "site", None)
    site = load_site_file(path) if path else validate_site(EMPTY_SITE)
    version = await store.save_site(site.model_dump(mode="json"))
    return site, version


def _sync_robot_tokens(tokens: TokenStore, site: Site, known: dict[str, str]) -> None:
    """Robots' tokens come from the site: add new ones, drop removed or changed ones."""
    wanted = {r.token: r.name for r in site.robots}
    for token in list(known):
        if wanted.get(token) != known[token]:
            tokens.remove(token)
            del known[token]
    for token, name in wanted.items():
        if token not in known:
            tokens.add(token, name, Role.ROBOT)
            known[token] = name


async def watch_robot_links(
    hub: Any, sites: SiteService, tasks: TaskManager, period_s: float = 0.25
) -> None:
    """Tell the managers when a robot's WebSocket link comes up or drops.

    A robot the Task Manager believes online but that has no hub link any more is announced
    as disconnected, even if its whole connection fell between two looks.
    """
    endpoint = hub.endpoint("link_watcher")
    connected: set[str] = set()
    try:
        while True:
            robots = {r.name for r in sites.site.robots}
            now = robots & set(hub.clients)
            believed = {name for name, info in tasks.robots.items() if info.online}
            for name in sorted(now - connected):
                endpoint.publish("robot_connected", {"robot": name})
            for name in sorted(((connected | believed) & robots) - now):
                endpoint.publish("robot_disconnected", {"robot": name})
            connected = now
            await asyncio.sleep(period_s)
    finally:
        endpoint.close()


@contextlib.asynccontextmanager
async def server_brain(app: FastAPI) -> AsyncIterator[None]:
    settings = app.state.settings
    hub = app.state.hub
    engine = make_engine(settings.db_url)
    try:
        await migrate(engine)
        store = DbStore(make_sessionmaker(engine))
        store.start()
        try:
            site, version = await _initial_site(app, store)
            sites = SiteService(site, version, store)
            # Seconds on a large site: built in a thread so the event loop keeps serving.
            graph = await asyncio.to_thread(SiteGraph, site)

            def log_event(kind: str, data: dict[str, Any]) -> None:
                store.record_event(kind, "traffic_manager", data)

            traffic = TrafficManager(
                hub.endpoint("traffic_manager"), site, graph=graph, on_event=log_event
            )
            tasks = TaskManager(hub.endpoint("task_manager"), site, graph=graph, store=store)
            buttons = ButtonWatcher(hub.endpoint("buttons"), tasks, site)
            known_tokens: dict[str, str] = {}
            _sync_robot_tokens(app.state.tokens, site, known_tokens)

            async def on_site(new: Site) -> None:
                new_graph = await asyncio.to_thread(SiteGraph, new)
                # One synchronous block: every module switches to the new site at once.
                traffic.load_site(new, new_graph)
                tasks.load_site(new, new_graph)
                buttons.load_site(new)
                _sync_robot_tokens(app.state.tokens, new, known_tokens)

            sites.on_change(on_site)
            logger = hub.endpoint("event_log")

            def log_message(msg: Message) -> None:
                store.record_event(msg.type, msg.source, msg.payload)

            for pattern in LOGGED_TYPES:
                logger.subscribe(pattern, log_message, tap=True)
            tasks.restore(await store.load_open_tasks())
            traffic.start()
            tasks.start()
            buttons.start()
            app.state.store = store
            app.state.sites = sites
            app.state.task_manager = tasks
            app.state.traffic = traffic
            links = asyncio.get_running_loop().create_task(
                watch_robot_links(hub, sites, tasks), name="robot-link-watcher"
            )
            try:
                yield
            finally:
                links.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await links
                buttons.stop()
                await tasks.stop()
                traffic.stop()
                logger.close()
        finally:
            await store.stop()
    finally:
        await engine.dispose()
