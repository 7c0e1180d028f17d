"""The server brain wired in order: database, site, Traffic Manager, Task Manager, building
buttons, event log, robot links and the offline-lock watcher (listed in backend.app.COMPONENTS).

One flat exit stack, like the robot agent's (robot_agent/agent.py): each part is given back,
newest first, when the server stops or when a later part fails to start. Its parts' subjects
have their own modules: the robots' tokens (backend/site/tokens.py), what the event log keeps
(backend/event_log.py), robot links (backend/robot_links.py), the offline-lock watcher
(backend/traffic/offline.py).
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from fastapi import FastAPI

from backend.accounts.audit import AUDIT_KINDS
from backend.alerts import AlertStore
from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.event_log import keep_in_log
from backend.fencing import deciding_endpoint
from backend.health import ComponentState
from backend.reports.figures import Reports
from backend.reports.rollup import Rollups, node_positions
from backend.robot_links import announce_robot_links
from backend.site.graph_build import build_site_graph
from backend.site.offloop import release
from backend.site.service import EMPTY_SITE, SiteService
from backend.site.tokens import (
    InsecureSite,
    hash_robot_tokens,
    sync_robot_tokens,
    weak_robot_tokens,
)
from backend.state import app_state
from backend.tasks.buttons import ButtonWatcher
from backend.tasks.lifts import lift_queue
from backend.tasks.manager import TaskManager
from backend.traffic.manager import TrafficManager
from backend.traffic.offline import watch_offline_locks
from guidebot.service import Service
from guidebot.site.schema import Site
from guidebot.site.validate import validate_site
from guidebot.site.yamlio import load_site_file

__all__ = ["ServerBrain", "server_brain"]

REPORT_GRACE_S = 15.0
"""With several processes: how long a restored task its robot no longer names waits for the
robot's task_ended (TaskManager.report_grace_s)."""


async def _initial_site(store: DbStore, path: Path | None) -> tuple[Site, int]:
    """The database wins; the site file ``path`` is imported only into an empty database."""
    stored = await store.load_site()
    if stored is not None:
        version, data = stored
        site = validate_site(data)
        hashed = hash_robot_tokens(site)
        if hashed is not site:  # stored before tokens were hashed: store the digests now
            version = await store.save_site(hashed.model_dump(mode="json"))
        return hashed, version
    site = load_site_file(path) if path else validate_site(EMPTY_SITE)
    site = hash_robot_tokens(site)
    version = await store.save_site(site.model_dump(mode="json"))
    return site, version


class ServerBrain(Service):
    """Starts the brain's parts on ``app.state`` (store, sites, task_manager, traffic,
    alerts); ``stop`` gives them back in reverse order."""

    def __init__(self, app: FastAPI) -> None:
        super().__init__()
        self.app = app

    async def on_start(self) -> None:
        app = self.app
        settings = app.state.settings
        hub = app.state.hub
        health = app.state.health
        engine = make_engine(settings.db_url)
        self.on_cleanup(engine.dispose)
        try:
            await migrate(engine)
        except Exception as exc:
            health.set("database", ComponentState.failed, f"{type(exc).__name__}: {exc}")
            raise
        leadership = app_state(app).leadership  # several server processes
        store = DbStore(
            make_sessionmaker(engine),
            epoch=None if leadership is None else leadership.fencing_epoch,
            retention_s=settings.event_retention_days * 86400 or None,
            prune_every_s=settings.event_prune_every_s,
            audit_kinds=AUDIT_KINDS,
            audit_retention_s=settings.audit_retention_days * 86400 or None,
        )
        await self.enter(store)
        health.set("database", ComponentState.ok, engine.url.get_backend_name())

        site, version = await _initial_site(store, settings.site)
        if not settings.development and (problems := weak_robot_tokens(site)):
            raise InsecureSite(
                f"refusing to start with environment={settings.environment!r}: "
                + "; ".join(problems)
                + " (give the robots real tokens in the site, or GUIDEBOT_ENVIRONMENT="
                "development)"
            )
        sites = SiteService(site, version, store)
        rollups = Rollups(store.sessionmaker, node_positions(site))
        # Seconds on a large site: built off the event loop (threads, worker processes).
        workers = settings.site_workers
        graph = await build_site_graph(site, workers)

        def log_event(kind: str, data: dict[str, Any]) -> None:
            store.record_event(kind, "traffic_manager", data)

        alerts_endpoint = hub.endpoint("alerts")
        self.on_cleanup(alerts_endpoint.close)
        alerts = AlertStore(alerts_endpoint.publish, store.record_event)
        await alerts.restore(store.events)
        traffic = TrafficManager(
            deciding_endpoint(app, "traffic_manager"),
            site,
            graph=graph,
            on_event=log_event,
            alerts=alerts,
        )
        tasks = TaskManager(
            deciding_endpoint(app, "task_manager"),
            site,
            graph=graph,
            store=store,
            report_grace_s=REPORT_GRACE_S if settings.broker_url else 0.0,
            alerts=alerts,
        )
        # Elevator-aware dispatch: the lifts' queue as the Traffic Manager's locks hold it.
        tasks.lifts.queue = lift_queue(traffic.lock_views, lambda: traffic.graph)
        buttons = ButtonWatcher(deciding_endpoint(app, "buttons"), tasks, site)
        known_tokens: dict[str, str] = {}
        sync_robot_tokens(app.state.tokens, site, known_tokens)

        async def on_site(new: Site) -> None:
            new_graph = await build_site_graph(new, workers)
            retired = [traffic.graph, tasks.graph]  # freed in a thread, not on the loop
            # One synchronous block: every module switches to the new site at once.
            traffic.load_site(new, new_graph)
            tasks.load_site(new, new_graph)
            buttons.load_site(new)
            sync_robot_tokens(app.state.tokens, new, known_tokens)
            rollups.positions = node_positions(new)
            await release(retired)

        sites.on_change(on_site)
        logger = hub.endpoint("event_log")
        self.on_cleanup(logger.close)
        self.on_cleanup(self._mark_stopped)  # after the managers below have stopped
        # The log's mark of a clean stop (the reports count the time to the next start as the
        # server down), after the managers' last events and before the store's last write.
        self.on_cleanup(lambda: store.record_event("server_stopped", "server", {}))
        keep_in_log(logger, store.record_event)
        # The log's mark of a new server life. The locks of the last one are read first and
        # held again (logged as grants with ``restored``) until their robots report.
        held = await store.lock_holders()
        store.record_event("server_started", "server", {"site_version": version})
        restored = await store.load_open_tasks()
        tasks.restore_service(await store.out_of_service())  # before restore() dispatches
        tasks.restore(restored)
        await self.enter(traffic)
        traffic.restore_locks(held)
        traffic.await_resync(
            {t.robot for t in restored if t.robot and not t.final}, settings.lock_resync_s
        )
        health.set("traffic_manager", ComponentState.ok)
        await self.enter(tasks)
        health.set("task_manager", ComponentState.ok)
        await self.enter(buttons)
        app.state.store = store
        app.state.sites = sites
        app.state.task_manager = tasks
        app.state.traffic = traffic
        app.state.alerts = alerts
        app.state.reports = Reports(rollups, store.flush)
        self.spawn(rollups.run_periodically(settings.report_rollup_every_s), name="report-rollups")
        self.spawn(
            watch_offline_locks(traffic, settings.lock_offline_grace_s),
            name="offline-lock-watcher",
        )
        self.on_cleanup(announce_robot_links(hub, sites))

    def _mark_stopped(self) -> None:
        for name in ("task_manager", "traffic_manager", "database"):
            self.app.state.health.set(name, ComponentState.stopped)


@contextlib.asynccontextmanager
async def server_brain(app: FastAPI) -> AsyncIterator[None]:
    """The brain as an app component (backend.app.COMPONENTS)."""
    async with ServerBrain(app):
        yield
