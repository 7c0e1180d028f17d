"""Charging between tours (docs/server.md, "Charging"): what each robot's battery lasts, whether
it can finish a tour before it, and which station a robot sent to charge takes.

- Each robot's drain (battery fraction per second away from a charger) is learned from its
  ``robot_state`` readings: a running average over falling readings, never while it charges,
  and never from a fall no work explains (a fault: battery_rates.py ``is_jump``).
- A robot is given a visitor's task only if, at that drain, its battery after the task (its
  foretold real duration, backend/tasks/eta.py) stays above ``finish_floor``: half-way between
  its ``battery_panic`` and ``battery_low``. Until its drain is known, ``battery_low`` alone
  decides (backend/tasks/choice.py, ``available``).
- Idle robots charge opportunistically (backend/tasks/choice.py, ``idle_errands``): the
  emptiest first when stations are fewer than robots, and one waiting at a wait point below
  ``OPPORTUNISTIC_BELOW`` goes to a station that frees up.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Collection, Iterable

from backend.tasks.battery_rates import fleet_rate, is_jump
from backend.tasks.choice import OPPORTUNISTIC_BELOW, Distances, nearest
from backend.tasks.robots import RobotInfo
from guidebot.site.schema import ChargingStation, Site

__all__ = [
    "CHARGING_MODES",
    "OPPORTUNISTIC_BELOW",
    "can_finish",
    "finish_floor",
    "learn_drain",
    "station_for",
]

log = logging.getLogger(__name__)

CHARGING_MODES = frozenset({"charging"})
"""robot_state modes in which the battery fills (readings then teach nothing of the drain)."""
MIN_SPAN_S = 5.0
"""Readings closer than this are not compared (a battery level is coarse)."""


def learn_drain(
    robot: RobotInfo, level: float, mode: str, now: float, fleet: Iterable[RobotInfo] = ()
) -> None:
    """A battery reading: the drain is the running average of the falling spans; a fall that
    its drain (else the ``fleet``'s) does not explain is a jump and teaches nothing."""
    if mode in CHARGING_MODES or mode == "offline":
        robot.battery_at = None
        return
    last = robot.battery_at
    if last is None or level > last[1]:
        robot.battery_at = (now, level)
        return
    span = now - last[0]
    if span < MIN_SPAN_S:
        return
    rate = (last[1] - level) / span
    robot.battery_at = (now, level)
    if rate <= 0 or not math.isfinite(rate):
        return
    known = robot.drain_per_s
    if known is None:
        known = fleet_rate(r.drain_per_s for r in fleet if r is not robot)
    if is_jump(last[1] - level, span, known):
        log.info(
            "%s: battery fell from %.2f to %.2f in %.0f s: a jump, not learned as drain",
            robot.name,
            last[1],
            level,
            span,
        )
        return
    robot.drain_per_s = rate if robot.drain_per_s is None else 0.7 * robot.drain_per_s + 0.3 * rate


def finish_floor(robot: RobotInfo) -> float:
    """The lowest level a robot may foresee at the end of a visitor's task."""
    cfg = robot.config
    return cfg.battery_panic + (cfg.battery_low - cfg.battery_panic) / 2


def can_finish(robot: RobotInfo, task_s: float | None) -> bool:
    """The robot's battery lasts ``task_s`` real seconds (unknown drain or duration: yes)."""
    if robot.drain_per_s is None or task_s is None or not math.isfinite(task_s):
        return True
    return robot.battery - robot.drain_per_s * task_s >= finish_floor(robot)


def station_for(
    robot: RobotInfo,
    site: Site,
    taken: Collection[str | None],
    distances_to: Callable[[str], Distances],
) -> ChargingStation | None:
    """The station a robot sent to charge goes to: the one it stands at, else the nearest one
    no robot charges at or stands at (``taken``), else the nearest at all (it queues there)."""
    stations: Iterable[ChargingStation] = site.charging_stations
    here = next((s for s in stations if s.node == robot.node), None)
    if here is not None:
        return here
    free = [s for s in site.charging_stations if s.id not in taken]
    return nearest(robot.node, free or site.charging_stations, distances_to)
