"""Scaled time for the robot agent: simulated seconds run ``time_scale`` times faster.

Every module that waits "robot time" (speech, time-outs, the simulated base) goes through one
Clock so tests and demos can speed a whole robot up with one factor.
"""

from __future__ import annotations

import asyncio
import time

__all__ = ["Clock"]


class Clock:
    """Robot time = wall time x time_scale, measured from a monotonic origin."""

    def __init__(self, time_scale: float = 1.0) -> None:
        if time_scale <= 0:
            raise ValueError(f"time_scale must be positive, got {time_scale}")
        self.time_scale = time_scale
        self._origin = time.monotonic()

    def now(self) -> float:
        """Robot seconds since the clock was made."""
        return (time.monotonic() - self._origin) * self.time_scale

    def wall(self, robot_seconds: float) -> float:
        """Wall seconds that ``robot_seconds`` of robot time take."""
        return robot_seconds / self.time_scale

    async def sleep(self, robot_seconds: float) -> None:
        await asyncio.sleep(max(0.0, robot_seconds) / self.time_scale)
