"""The FastAPI application factory of the central server.

``create_app(settings)`` builds nothing until the lifespan starts: then the hub, the token store,
every component of ``COMPONENTS`` (Task Manager, Traffic Manager, BuildingInterface, ...) in
order and, with ``hub_ws_port`` set, the hub's own listener; torn down in reverse. Routers of
``ROUTERS`` are included by the factory.

To add a server module, append ONE line to the list it belongs to:
- ``COMPONENTS``: a callable taking the app and returning an async context manager; it runs
  while the server runs and may keep its service on ``app.state``;
- ``ROUTERS``: an APIRouter (import it at the top of this file).
"""

from __future__ import annotations

import contextlib
import logging
import re
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager
from typing import Any

import uvicorn
from fastapi import APIRouter, Depends, FastAPI, HTTPException
from fastapi.responses import Response

import guidebot
from backend.accounts import routes as accounts_routes
from backend.accounts.audit import AuditTrail
from backend.accounts.component import accounts
from backend.api import ROUTERS as api_routers
from backend.api.errors import install_error_handlers
from backend.api.limits import BodyLimit
from backend.api.methods import install_method_answers
from backend.api.openapi import install_contract_openapi
from backend.api.warmup import warm_routes
from backend.auth import Authenticator, Role, TokenStore
from backend.bookings import routes as bookings_routes
from backend.bookings.component import bookings
from backend.brain import server_brain
from backend.building import routes as building_routes
from backend.building.component import building_interface
from backend.closures import routes as closures_routes
from backend.closures.component import closures
from backend.cluster import FollowerRest, cluster_report, clustered
from backend.console import fleet as console_fleet
from backend.console import routes as console_routes
from backend.console.component import console
from backend.emergency import routes as emergency_routes
from backend.emergency.component import emergency
from backend.health import ComponentState, HealthBoard
from backend.hub import Hub
from backend.hub import routes as hub_routes
from backend.hub import websocket as hub_websocket
from backend.hub.asgi_protocol import LingeringWebSocketProtocol
from backend.hub.listener import hub_listener
from backend.metrics import routes as metrics_routes
from backend.metrics.component import metrics
from backend.net_library.component import net_library
from backend.notify import routes as notify_routes
from backend.notify.component import notify
from backend.ratelimit import RateLimiter
from backend.reports import api as reports_routes
from backend.rest.deps import ERRORS
from backend.rest.query import known_query
from backend.rgm import rgm
from backend.settings import Settings
from backend.site.component import site_editor
from backend.state import AppState, app_state
from backend.tasks.inbound import limit_task_requests
from backend.vda5050 import routes as vda5050_routes
from backend.vda5050.component import vda5050
from backend.webpages import WebFiles, page

__all__ = ["COMPONENTS", "ROUTERS", "create_app", "uvicorn_config"]

log = logging.getLogger(__name__)

Component = Callable[[FastAPI], AbstractAsyncContextManager[None]]

# Server modules started in this order after the hub (and stopped in reverse). One line each.
COMPONENTS: list[Component] = [
    metrics,
    server_brain,
    accounts,
    building_interface,
    emergency,
    closures,
    bookings,
    rgm,
    net_library,
    site_editor,
    console,
    vda5050,
    notify,
]

# REST/WebSocket routers of the server modules. One line each.
ROUTERS: list[APIRouter] = [
    hub_websocket.router,
    hub_routes.router,
    *api_routers,
    building_routes.router,
    emergency_routes.router,
    closures_routes.router,
    console_routes.router,
    console_fleet.router,
    metrics_routes.router,
    reports_routes.router,
    vda5050_routes.router,
    accounts_routes.router,
    notify_routes.router,
    bookings_routes.router,
]


def _load_tokens(settings: Settings) -> TokenStore:
    tokens = TokenStore()
    tokens.add(settings.admin_token, "admin", Role.ADMIN)
    for static in settings.tokens:
        tokens.add(static.token, static.name, static.role)
    return tokens


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the server app; ``settings`` default to the environment (GUIDEBOT_*)."""
    settings = settings if settings is not None else Settings()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        app.state.settings = settings
        app.state.health = health_board = HealthBoard()
        app.state.tokens = _load_tokens(settings)
        app.state.auth = Authenticator(
            app.state.tokens,
            RateLimiter(
                per_minute=settings.sign_in_failures_per_minute,
                burst=settings.sign_in_failure_burst,
            ),
        )
        app.state.task_limits = RateLimiter(
            per_minute=settings.task_requests_per_minute, burst=settings.task_request_burst
        )
        app.state.hub = Hub(
            queue_size=settings.hub_queue_size,
            coalesce_after=settings.hub_coalesce_after,
            batch_max=settings.hub_batch_max,
            linger=settings.hub_linger_ms / 1000,
            max_message_bytes=settings.hub_max_message_bytes,
        )
        limit_task_requests(app.state.hub.checks, app.state.task_limits)
        health_board.set("hub", ComponentState.ok)
        async with contextlib.AsyncExitStack() as stack:
            stack.callback(app.state.hub.close)
            stack.callback(health_board.set, "hub", ComponentState.stopped)
            if settings.broker_url:  # several processes: components run on the leader only
                # A server inside another program (the tests) stops itself, not that program.
                on_lost = app_state(app).on_lost_leadership
                await stack.enter_async_context(clustered(app, COMPONENTS, on_lost=on_lost))
            else:
                for component in COMPONENTS:
                    await stack.enter_async_context(component(app))
            app.state.hub_ws_port = None
            if settings.hub_ws_port is not None:  # opened last, as uvicorn opens /ws: all is up
                app.state.hub_ws_port = await stack.enter_async_context(
                    hub_listener(app, settings.host, settings.hub_ws_port)
                )
            await warm_routes(app)
            log.info("GuideBot server ready (%d components)", len(COMPONENTS))
            yield

    # /docs is Swagger UI served from web/ (web/api-docs, web/vendor/swagger-ui): FastAPI's own
    # pages load it from a CDN (blank offline) with an inline script (no CSP).
    app = FastAPI(
        title="GuideBot central server (JCentral)",
        version=guidebot.__version__,
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
        dependencies=[Depends(known_query)],  # unknown query parameters: 422 (rest/query.py)
    )
    app.state = AppState()  # the same State, typed (backend/state.py)
    app.state.settings = settings

    @app.get("/api/health", tags=["server"])
    async def health() -> dict[str, Any]:
        """Each component's state ("degraded" when one failed) and a glance at the hub: for
        load balancers, tests and the admin page; ``hub_ws_port`` is the hub's own listener's
        port (null: off). Always 200: read ``status``."""
        hub: Hub = app.state.hub
        building = app_state(app).building
        if building is not None:
            app.state.health.set("building_interface", *building.component_state())
        return {
            **app.state.health.report(),
            "environment": settings.environment,
            "clients": len(hub.clients),
            "endpoints": len(hub.bus.endpoint_names),
            "published": hub.bus.published,
            "hub_ws_port": app_state(app).hub_ws_port,
            **({"cluster": cluster} if (cluster := cluster_report(app)) else {}),
        }

    @app.get("/docs", include_in_schema=False)
    async def api_docs() -> Response:
        """The API documentation (Swagger UI on /openapi.json), from this server only."""
        path = settings.web_dir / "api-docs" / "index.html"
        if not path.is_file():
            raise HTTPException(404, f"{path} not found: no API docs page")
        return page(path)

    install_error_handlers(app)
    app.add_middleware(AuditTrail)
    app.add_middleware(BodyLimit, max_bytes=settings.max_body_bytes)
    if settings.broker_url:
        app.add_middleware(FollowerRest)
    for router in ROUTERS:
        app.include_router(router, responses=ERRORS)
    install_method_answers(app)  # after every route: what /api answers that none took
    install_contract_openapi(app)
    if settings.web_dir.is_dir():
        app.mount("/", WebFiles(directory=settings.web_dir, html=True), name="web")
    else:
        log.warning("web directory %s not found: no static pages", settings.web_dir)
    return app


def uvicorn_config(
    app: FastAPI, host: str, port: int, log_level: str = "warning", access_log: bool = True
) -> uvicorn.Config:
    """The server's uvicorn settings: sans-I/O websockets without compression (CPU matters).

    Browsers pass the hub token as ``?token=``: uvicorn's log lines are redacted. Without
    ``access_log`` no line per request is written (the demo's console stays readable).
    """
    config = uvicorn.Config(
        app,
        host=host,
        port=port,
        log_level=log_level,
        access_log=access_log,
        lifespan="on",
        ws=LingeringWebSocketProtocol,  # websockets-sansio, failing without a reset
        ws_per_message_deflate=False,
        ws_max_size=16 * 1024 * 1024,
        timeout_graceful_shutdown=5,
    )
    for name in ("uvicorn.error", "uvicorn.access"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, RedactTokens) for f in logger.filters):
            logger.addFilter(RedactTokens())
    return config


class RedactTokens(logging.Filter):
    """Replace ``token=<secret>`` in log lines by ``token=***``."""

    _pattern = re.compile(r"(token=)[^&\s\"']+")

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(
                self._pattern.sub(r"\1***", a) if isinstance(a, str) else a for a in record.args
            )
        if isinstance(record.msg, str):
            record.msg = self._pattern.sub(r"\1***", record.msg)
        return True
