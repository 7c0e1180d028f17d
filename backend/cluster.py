"""Several server processes: the broker bridge plus leadership (docs/scaling.md).

With ``--broker`` every process serves WebSocket clients and REST, and bridges its hub to the
others through Redis. The components that decide or own state (``server_brain``: database
migrations, Task Manager, Traffic Manager; ``building_interface``; the site editor, console and
RGM that use them) start only on the process that wins the PostgreSQL advisory lock, and are
rebuilt from the database and the robots' resync when another process wins after a leader died.
A follower accepts the site's robots (their token digests are read from the database at start)
and people's pages signed in by their session cookie (read from the database).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from collections.abc import AsyncIterator, Callable, Coroutine, Sequence
from contextlib import AbstractAsyncContextManager
from typing import Any

import orjson
from fastapi import FastAPI
from starlette.types import ASGIApp, Receive, Scope, Send

from backend.accounts.component import follower_sessions
from backend.db import DbStore, make_engine, make_sessionmaker
from backend.health import ComponentState
from backend.hub.broker import BrokerBridge, process_id
from backend.leadership import Leadership
from backend.robot_links import announce_links
from backend.site.tokens import hash_robot_tokens, sync_robot_tokens
from backend.state import app_state
from guidebot.site.validate import validate_site

__all__ = ["DECIDING", "LOST_LEADERSHIP_EXIT", "FollowerRest", "cluster_report", "clustered"]

log = logging.getLogger(__name__)

DECIDING = ("task_manager", "traffic_manager", "building_interface")
"""Health components that run on the leader only."""

Component = Callable[[FastAPI], AbstractAsyncContextManager[None]]


LOST_LEADERSHIP_EXIT = 75
"""The exit status of a leader that lost its lock (a supervisor restarts it as a follower)."""


def _stop_this_process() -> None:
    """Fencing: a leader that lost its lock exits at once, without the clean shutdown that would
    flush its write-behind task store: another process may already lead, and anything this one
    wrote now could overwrite that leader's decisions."""
    logging.shutdown()
    os._exit(LOST_LEADERSHIP_EXIT)


def _first_line(exc: BaseException) -> str:
    """The driver's own words (SQLAlchemy's message adds the statement and a link)."""
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


FOLLOWER_RETRY_S = 2.0
"""How often a follower that found no site in the database looks again."""


class _FollowerTokens:
    """Let the site's robots connect to a follower: their token digests, read from the database
    at start and again whenever the leader publishes a new site version (site_changed). A
    follower that starts before any site is stored tries again every ``FOLLOWER_RETRY_S``."""

    def __init__(self, app: FastAPI, db_url: str) -> None:
        self.app, self.db_url = app, db_url
        self.known: dict[str, str] = {}
        self.loaded = False
        self._warned = False
        self._reloads: set[asyncio.Task[None]] = set()

    async def load(self) -> bool:
        """Take the stored site's robot tokens; False when the database has no site yet."""
        engine = make_engine(self.db_url)
        try:
            stored = await DbStore(make_sessionmaker(engine)).load_site()
        except Exception as exc:  # no schema yet: the first leader has not migrated the database
            if not self._warned:
                self._warned = True
                log.warning(
                    "cluster: no site in the database yet (%s): robots connect to the leader",
                    _first_line(getattr(exc, "orig", None) or exc),
                )
            return False
        finally:
            await engine.dispose()
        if stored is None:
            return False
        site = hash_robot_tokens(validate_site(stored[1]))
        sync_robot_tokens(self.app.state.tokens, site, self.known)
        self.loaded = True
        return True

    def _spawn(self, job: Coroutine[Any, Any, Any]) -> None:
        task = asyncio.get_running_loop().create_task(job, name="follower-tokens")
        self._reloads.add(task)
        task.add_done_callback(self._reloads.discard)

    async def _until_loaded(self, leadership: Leadership) -> None:
        while True:  # polls the database: nothing to wait on until a leader has stored a site
            if leadership.leading or await self.load():
                return
            await asyncio.sleep(FOLLOWER_RETRY_S)

    def watch(self, hub: Any, leadership: Leadership) -> Callable[[], None]:
        """Reload on every broadcast site_changed while following (and until a first site is
        stored); returns the stop function."""
        endpoint = hub.endpoint("follower_site_watcher")

        def changed(_message: Any) -> None:
            if not leadership.leading:  # the leader's own components keep its tokens
                self._spawn(self.load())

        endpoint.subscribe("site_changed", changed)
        if not self.loaded:
            self._spawn(self._until_loaded(leadership))

        def stop() -> None:
            endpoint.close()
            for task in self._reloads:
                task.cancel()

        return stop


def _announce_links_while_following(hub: Any, leadership: Leadership) -> Callable[[], None]:
    """robot_connected / robot_disconnected for robots on this process while it follows (the
    leader's own watcher, in server_brain, announces them once it leads)."""
    return announce_links(hub, lambda _client: not leadership.leading, name="follower_link_watcher")


@contextlib.asynccontextmanager
async def clustered(
    app: FastAPI, components: Sequence[Component], *, on_lost: Callable[[], None] | None = None
) -> AsyncIterator[None]:
    """Bridge the hub through the broker; run ``components`` only while this process leads."""
    settings = app.state.settings
    hub, health = app.state.hub, app.state.health
    process = process_id() if settings.process_name is None else settings.process_name
    bridge = BrokerBridge(hub, settings.broker_url, origin=process)
    leadership = Leadership(
        settings.db_url,
        process,
        on_lost=on_lost or _stop_this_process,
        poll_s=settings.leader_poll_s,
        lease_s=settings.leader_lease_s,
    )
    app.state.broker, app.state.leadership = bridge, leadership
    hub.forwards_unknown = True
    # Robots' must-arrive messages are acknowledged where they are handled (backend/hub/acks.py).
    hub.decides = lambda: leadership.serving and leadership.may_decide()
    # Won but not serving yet: the deciding components are starting (docs/scaling.md).
    hub.starting = lambda: leadership.leading and not leadership.serving
    await bridge.start()
    tokens = _FollowerTokens(app, settings.db_url)
    await tokens.load()
    for name in ("database", *DECIDING):
        health.set(name, ComponentState.disabled, "follower: the leader runs it")
    stopping = asyncio.Event()

    async def lead() -> None:
        await leadership.won.wait()
        try:
            async with contextlib.AsyncExitStack() as stack:
                for component in components:
                    await stack.enter_async_context(component(app))
                log.info("cluster: %s runs the deciding components", process)
                leadership.serving = True
                try:
                    await stopping.wait()
                finally:
                    leadership.serving = False
        except Exception:
            log.exception("cluster: the deciding components failed on %s", process)
            raise

    stop_links = _announce_links_while_following(hub, leadership)
    stop_tokens = tokens.watch(hub, leadership)
    # People's sessions from the shared database, until the accounts component leads.
    async with follower_sessions(app):
        await leadership.start()
        leader_task = asyncio.get_running_loop().create_task(lead(), name="cluster-leader")
        try:
            yield
        finally:
            stopping.set()
            if not leadership.leading:
                leader_task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await leader_task
            stop_links()
            stop_tokens()
            await leadership.stop()
            await bridge.stop()


def cluster_report(app: FastAPI) -> dict[str, Any] | None:
    """/api/health's "cluster" section: this process, the leader, the epoch, the broker."""
    leadership: Leadership | None = app_state(app).leadership
    bridge: BrokerBridge | None = app_state(app).broker
    if leadership is None or bridge is None:
        return None
    fenced = sum(e.dropped for e in app_state(app).fenced_endpoints)
    return {**leadership.report(), "fenced": fenced, "broker": bridge.stats()}


class FollowerRest:
    """On a follower (and on a leader until its components are up), REST under /api (except
    /api/health) answers 503 and names the leader: the services behind it run on the leader
    only (docs/scaling.md)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        path = scope.get("path", "")
        if scope["type"] == "http" and path.startswith("/api/") and path != "/api/health":
            leadership: Leadership | None = app_state(scope["app"]).leadership
            if leadership is not None and not leadership.serving:
                body = orjson.dumps(
                    {
                        "detail": "this process follows: send REST to the leader",
                        "leader": leadership.leader,
                    }
                )
                headers = [(b"content-type", b"application/json"), (b"retry-after", b"1")]
                await send({"type": "http.response.start", "status": 503, "headers": headers})
                await send({"type": "http.response.body", "body": body})
                return
        await self.app(scope, receive, send)
