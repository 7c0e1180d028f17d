"""The watcher of locks whose holder went offline: the Traffic Manager decides about them
(release, keep, alert: docs/server.md "Lock policy"); this loop only asks it once a second."""

from __future__ import annotations

import asyncio
import logging

from backend.traffic.manager import TrafficManager

__all__ = ["watch_offline_locks"]

log = logging.getLogger(__name__)


async def watch_offline_locks(
    traffic: TrafficManager, grace_s: float, period_s: float = 1.0
) -> None:
    """Decide, once a second, about locks whose holder has been offline for ``grace_s``."""
    while True:
        await asyncio.sleep(period_s)
        try:
            traffic.check_offline_locks(grace_s)
        except Exception:
            log.exception("offline lock check failed")
