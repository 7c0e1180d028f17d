"""Traffic Manager: shortest paths over the site graph and restricted-area locks."""

from backend.traffic.graph import NoPath, PathResult, SiteGraph, UnknownNode
from backend.traffic.locks import AreaLocks, LockError, LockState, LockView
from backend.traffic.manager import TrafficManager

__all__ = [
    "AreaLocks",
    "LockError",
    "LockState",
    "LockView",
    "NoPath",
    "PathResult",
    "SiteGraph",
    "TrafficManager",
    "UnknownNode",
]
