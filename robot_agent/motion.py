"""Motion control: the base's pose from odometry, and velocity commands that drive it to a
point or turn it to a heading (closed loop, bumper pauses, base faults).

Route following (robot_agent/navigation.py) builds on it; the areas, doors and elevators on the
way are robot_agent/passage.py. Odometry arrives in the base's own frame; the map pose is
``R(dtheta) * odom + (tx, ty)``, re-anchored by the navigator (``relocalize``) on known nodes.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from enum import StrEnum

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.service import Service
from robot_agent.clock import Clock

__all__ = ["MotionControl", "NavState", "NavigationError", "wrap_angle"]

PROCESS_STALL_S = 0.1
"""Wall seconds between two turns of the drive loop beyond which the agent itself stood still
(a starved process, a paused VM): that time does not count against the goal's budget, which is
robot time and runs ``time_scale`` times faster than the wall clock in simulation. The same as
the simulated bases' longest step (``MAX_STEP_S``, robot_agent/sim_base.py and
robocan/sim/motor.py): they do not move through the rest of a longer gap, so it must not count
either (at 0.5 s a loaded machine's 0.3 s turns spent the budget three times faster than the
simulated robot drove: "stuck")."""

ODOM_PERIOD_MAX_S = 0.5
"""The longest gap between two odometry reports taken for the base's period (the loop's
gains follow it); a longer one is a stall of this process. Not ``PROCESS_STALL_S``: a base
reporting every 0.1 s (the simulated RoboCAN encoder) would then be taken for a faster one,
its gains doubled, and the robot would circle its goal 0.2 m away ("stuck")."""

ODOMETRY_TIMEOUT_S = 2.0
"""Wall seconds without odometry after which the base is given up ("no odometry from the
base"): seconds this process ran, a stall of its own not counted (``_next_odometry``)."""

ODOMETRY_SLICE_S = 0.25
"""The odometry watchdog counts silence in slices this long (``ODOMETRY_TIMEOUT_S``)."""


class NavigationError(Exception):
    """A goal could not be reached; ``reason`` is sent in navigation_failed (the payload
    ``guidebot.payloads.petri.NavigationFailed``)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class NavState(StrEnum):
    IDLE = "idle"
    PLANNING = "planning"
    MOVING = "moving"
    WAITING_AREA = "waiting_area"
    WAITING_DOOR = "waiting_door"
    WAITING_ELEVATOR = "waiting_elevator"
    RIDING = "riding"
    DOOR_BLOCKED = "door_blocked"
    BUMPED = "bumped"
    FAULT = "fault"


def wrap_angle(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


class MotionControl(Service):
    """Pose and velocity loop of one robot's base (an endpoint on the on-board bus)."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        clock: Clock,
        robot: str,
        *,
        max_speed: float = 0.7,
        max_turn: float = 1.5,
        tolerance_m: float = 0.15,
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.clock = clock
        self.robot = robot
        self.max_speed = max_speed
        self.max_turn = max_turn
        self.tolerance_m = tolerance_m
        self.x = self.y = self.theta = 0.0
        self.speed = 0.0
        self.state = NavState.IDLE
        self.fault: str | None = None
        # Odometry frame -> map frame: map = R(dtheta) * odom + (tx, ty).
        self._odom: tuple[float, float, float] | None = None
        self._dtheta = 0.0
        self._tx = self._ty = 0.0
        self._odom_dt = 0.05
        self._odom_last = 0.0
        self._bumped_until = -1.0
        self._odom_event = asyncio.Event()
        self._last_cmd: tuple[float, float, float] = (math.nan, math.nan, 0.0)

    def _on_odometry(self, message: Message) -> None:
        p = message.payload
        ox, oy, oth = float(p.get("x", 0.0)), float(p.get("y", 0.0)), float(p.get("theta", 0.0))
        now = time.monotonic()
        if self._odom_last and now - self._odom_last < ODOM_PERIOD_MAX_S:
            # The base's period, for the loop's gains; a stall of this process is not one.
            self._odom_dt = 0.8 * self._odom_dt + 0.2 * (now - self._odom_last)
        self._odom_last = now
        self._odom = (ox, oy, oth)
        c, s = math.cos(self._dtheta), math.sin(self._dtheta)
        self.x = c * ox - s * oy + self._tx
        self.y = s * ox + c * oy + self._ty
        self.theta = wrap_angle(oth + self._dtheta)
        self.speed = float(p.get("v", 0.0))
        self._odom_event.set()

    def _check_fault(self) -> None:
        if self.fault is not None:
            raise NavigationError(f"base fault: {self.fault}")

    # -- closed loop ------------------------------------------------------------------------------

    async def drive_to(
        self, x: float, y: float, *, stop: bool = True, clear: Callable[[], bool] | None = None
    ) -> bool:
        """Closed loop on odometry: turn towards the target, then drive with steering.

        Raises NavigationError "stuck" once the budget (robot time: 20 s plus four times the
        straight-line travel time) is spent; bumper pauses and stalls of this process itself
        (``PROCESS_STALL_S``) extend it. Returns False (stopped) as soon as ``clear()`` says
        the way is no longer free."""
        self.state = NavState.MOVING
        distance = math.hypot(x - self.x, y - self.y)
        budget = self.clock.now() + 20.0 + 4.0 * distance / self.max_speed
        fresh = self._odom is not None  # first command at once, from the pose we have
        turn_at = time.monotonic()
        while True:
            if not fresh:
                await self._next_odometry()
            fresh = False
            now = time.monotonic()
            stalled = now - turn_at - PROCESS_STALL_S
            if stalled > 0:
                budget += stalled * self.clock.time_scale
            turn_at = now
            self._check_fault()
            if self.clock.now() < self._bumped_until:
                self.state = NavState.BUMPED
                self._send_velocity(0.0, 0.0)
                budget += self._odom_dt * self.clock.time_scale
                continue
            self.state = NavState.MOVING
            dx, dy = x - self.x, y - self.y
            dist = math.hypot(dx, dy)
            if dist < self.tolerance_m:
                break
            if clear is not None and not clear():
                self._send_velocity(0.0, 0.0, force=True)
                return False
            if self.clock.now() > budget:
                raise NavigationError(f"stuck {dist:.2f} m from ({x:.1f}, {y:.1f})")
            err = wrap_angle(math.atan2(dy, dx) - self.theta)
            step = max(1e-3, self._odom_dt * self.clock.time_scale)
            w = max(-self.max_turn, min(self.max_turn, 0.7 * err / step))
            v = 0.0 if abs(err) > 0.35 else min(self.max_speed, 0.7 * dist / step) * math.cos(err)
            self._send_velocity(v, w)
        if stop:
            self._send_velocity(0.0, 0.0, force=True)
        return True

    async def turn_to(self, heading: float) -> None:
        budget = self.clock.now() + 20.0
        while True:
            await self._next_odometry()
            self._check_fault()
            err = wrap_angle(heading - self.theta)
            if abs(err) < 0.08 or self.clock.now() > budget:
                break
            step = max(1e-3, self._odom_dt * self.clock.time_scale)
            self._send_velocity(0.0, max(-self.max_turn, min(self.max_turn, 0.7 * err / step)))
        self._send_velocity(0.0, 0.0, force=True)

    async def _next_odometry(self) -> None:
        """Wait for the base's next report; NavigationError after ``ODOMETRY_TIMEOUT_S`` of
        silence, counted in slices of ``ODOMETRY_SLICE_S``: a slice the process itself stood
        still through counts as one slice, so the base gets a turn to report after a stall
        (its report, due meanwhile, used to come after the watchdog's expiry)."""
        self._odom_event.clear()
        silent = 0.0
        while True:
            began = time.monotonic()
            try:
                async with asyncio.timeout(ODOMETRY_SLICE_S):  # not wait_for: see _wait_until
                    await self._odom_event.wait()
                return
            except TimeoutError:
                silent += min(time.monotonic() - began, ODOMETRY_SLICE_S)
            if silent >= ODOMETRY_TIMEOUT_S:
                raise NavigationError("no odometry from the base") from None

    def halt(self, *, force: bool = True) -> None:
        """Command the base to stand still. ``force``: even when the last command was the same
        (without it, a repeat within half a second is skipped)."""
        self._send_velocity(0.0, 0.0, force=force)

    def _send_velocity(self, v: float, w: float, *, force: bool = False) -> None:
        last_v, last_w, last_t = self._last_cmd
        now = time.monotonic()
        if not force and abs(v - last_v) < 0.01 and abs(w - last_w) < 0.01 and now - last_t < 0.5:
            return
        self._last_cmd = (v, w, now)
        self.ep.publish("set_velocity", {"v": round(v, 4), "w": round(w, 4)})
