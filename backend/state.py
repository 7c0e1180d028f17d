"""The application state, typed: what the app factory and its components put on ``app.state``.

Starlette's ``app.state`` takes any name and reads it as ``Any``; a misspelt name or a part that
is not running only shows at run time. ``app_state(app)`` is the same state (the same values,
written and read in place) under a class that names each entry with its type, so mypy checks
every read. A part that may not run here (a follower, a site without a building, a component
not started yet or stopped) is typed ``X | None`` and reads as None while it is not set; the
entries ``create_app`` sets before anything runs (settings, hub, ...) raise AttributeError
when missing, as before.

The types are imported for the type checker only: this module imports nothing of the server
at run time, so every layer may read it (the import-linter contracts leave type-only imports
out, docs/architecture.md "Inside the server")."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from starlette.applications import Starlette
from starlette.datastructures import State

if TYPE_CHECKING:
    from backend.accounts.cookies import CookieGate
    from backend.accounts.oidc import SingleSignOn
    from backend.accounts.passkeys import PasskeyService
    from backend.accounts.service import AccountService
    from backend.alerts import AlertStore
    from backend.auth import Authenticator, TokenStore
    from backend.bookings.schedule import BookingScheduler
    from backend.bookings.service import BookingService
    from backend.building.interface import BuildingInterface
    from backend.closures.service import ClosureService
    from backend.console.feed import ConsoleFeed
    from backend.console.robocan import RobocanBook
    from backend.db.store import DbStore
    from backend.emergency.service import EmergencyService
    from backend.fencing import FencedEndpoint
    from backend.health import HealthBoard
    from backend.hub.broker import BrokerBridge
    from backend.hub.core import Hub
    from backend.leadership import Leadership
    from backend.metrics.server import ServerMetrics
    from backend.net_library.service import NetPublisher
    from backend.notify.service import Notifier
    from backend.ratelimit import RateLimiter
    from backend.reports.figures import Reports
    from backend.settings import Settings
    from backend.site.draft import SiteDrafts
    from backend.site.rollout import RolloutTracker
    from backend.site.service import SiteService
    from backend.tasks.manager import TaskManager
    from backend.traffic.manager import TrafficManager
    from backend.vda5050.master import MasterControl
    from petri_nets.dispatch import Dispatch

__all__ = ["AppState", "app_state"]


class AppState(State):
    """``app.state`` with its names and types (who sets each: the comment on its group)."""

    # backend/app.py, before anything runs
    settings: Settings
    health: HealthBoard
    tokens: TokenStore
    auth: Authenticator
    task_limits: RateLimiter
    hub: Hub
    hub_ws_port: int | None  # the hub's own WebSocket listener, when it runs
    on_lost_leadership: Callable[[], None] | None  # backend/testing.py's in-process leader

    # backend/brain.py (server_brain), on the leader
    store: DbStore | None
    sites: SiteService | None
    task_manager: TaskManager | None
    traffic: TrafficManager | None
    alerts: AlertStore | None
    reports: Reports | None

    # backend/cluster.py and backend/fencing.py, with several server processes
    broker: BrokerBridge | None
    leadership: Leadership | None
    fenced_endpoints: list[FencedEndpoint]  # reads as [] until the first one

    # the components of backend.app.COMPONENTS, each while it runs
    metrics: ServerMetrics | None
    rgm: Dispatch | None
    building: BuildingInterface | None
    emergency: EmergencyService | None
    closures: ClosureService | None
    bookings: BookingService | None
    booking_scheduler: BookingScheduler | None
    net_library: NetPublisher | None
    notify: Notifier | None
    site_drafts: SiteDrafts | None
    site_rollout: RolloutTracker | None
    console: ConsoleFeed | None
    robocan: RobocanBook | None
    fleet_pause: dict[str, Any] | None  # backend/console/fleet.py: who paused the fleet
    accounts: AccountService | None
    passkeys: PasskeyService | None
    sso: SingleSignOn | None
    sessions: CookieGate | None
    vda5050: MasterControl | None

    def __getattr__(self, key: str) -> Any:
        try:
            return self._state[key]
        except KeyError:
            pass
        if key in _NONE_UNTIL_SET:
            return None
        if key in _EMPTY_UNTIL_SET:
            return []
        message = "'{}' object has no attribute '{}'"
        raise AttributeError(message.format(self.__class__.__name__, key))


_NONE_UNTIL_SET = frozenset(
    name for name, kind in AppState.__annotations__.items() if kind.endswith("| None")
)
"""The entries typed ``X | None``: None while their part does not run."""
_EMPTY_UNTIL_SET = frozenset(
    name for name, kind in AppState.__annotations__.items() if kind.startswith("list[")
)


def app_state(app: Starlette) -> AppState:
    """``app.state`` typed (the app's own AppState, or a typed view of the same values)."""
    state = app.state
    if isinstance(state, AppState):
        return state
    return AppState(state._state)
