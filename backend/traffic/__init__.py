"""Traffic Manager: routes and restricted-area locks (the site graph is guidebot.site.graph)."""

from backend.traffic.locks import AreaLocks, LockError, LockState, LockView
from backend.traffic.manager import TrafficManager

__all__ = [
    "AreaLocks",
    "LockError",
    "LockState",
    "LockView",
    "TrafficManager",
]
