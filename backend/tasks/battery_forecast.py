"""What a robot's battery will be at a coming time (docs/server.md, "Bookings" and "Charging"):
its charge rate, learned from its ``robot_state`` readings as its drain is (charging.py), and
its level if it works on until then or charges meanwhile. The bookings' reservations ask it
whether a robot lasts until its booked tour ends, and when a robot must start charging to
(backend/bookings/reserve.py, "charge ahead"); the visitors' waits ask it how long a robot
charges before it can take a tour it is short of (backend/tasks/eta.py)."""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable

from backend.tasks.battery_rates import fleet_rate, is_jump
from backend.tasks.charging import MIN_SPAN_S, finish_floor
from backend.tasks.robots import RobotInfo

__all__ = [
    "CHARGED",
    "DEFAULT_CHARGE_PER_DRAIN",
    "charge_first_s",
    "charge_rate",
    "charged_level",
    "lasts_from",
    "latest_charge_start",
    "learn_charge",
]

CHARGED = 0.95
"""A charge ends at this level (the robot's battery monitor stops there; robot_agent/battery.py
``full``), and a robot due to charge is free again (backend/tasks/presence.py)."""
log = logging.getLogger(__name__)

DEFAULT_CHARGE_PER_DRAIN = 2.0
"""Until any robot of the fleet has charged (then the fleet's learned rate stands in), a robot
is taken to charge twice as fast as it drains: a guide robot works a day of 6 to 8 hours on a
charge of 3 to 4, and the simulated robot fills in 1 hour what it empties moving in 2. Its
learned drain counts its standing spans too (slower), so this errs on the slow side. (It was
as fast as it drains: the soak's first wave, before any robot had charged, reserved robots to
charge a quarter of an hour ahead of their bookings.)"""


def learn_charge(
    robot: RobotInfo, level: float, mode: str, now: float, fleet: Iterable[RobotInfo] = ()
) -> None:
    """A battery reading: the charge rate is the running average of the rising spans (a robot
    on its charge task may say ``busy`` rather than ``charging`` while it fills: a rising
    level is what tells; a first reading, a level that fell, or ``offline`` start again); a
    rise its rate (else the ``fleet``'s) does not explain is a jump and teaches nothing."""
    if mode == "offline":
        robot.charge_at = None
        return
    last = robot.charge_at
    if last is None or level <= last[1]:
        robot.charge_at = (now, level)
        return
    span = now - last[0]
    if span < MIN_SPAN_S:
        return  # too close to tell
    rate = (level - last[1]) / span
    robot.charge_at = (now, level)
    if level >= CHARGED or not math.isfinite(rate):
        return  # full: the charger tapers or has stopped
    known = robot.charge_per_s
    if known is None:
        known = fleet_rate(r.charge_per_s for r in fleet if r is not robot)
    if is_jump(level - last[1], span, known):
        log.info(
            "%s: battery rose from %.2f to %.2f in %.0f s: a jump, not learned as charge",
            robot.name,
            last[1],
            level,
            span,
        )
        return
    old = robot.charge_per_s
    robot.charge_per_s = rate if old is None else 0.7 * old + 0.3 * rate


def charge_rate(robot: RobotInfo, fleet: Iterable[RobotInfo] = ()) -> float | None:
    """Battery fraction per second on a charger: its learned one, else the one the other
    robots of the ``fleet`` learned (their median), else its drain times
    ``DEFAULT_CHARGE_PER_DRAIN``; None when none is known."""
    if robot.charge_per_s is not None:
        return robot.charge_per_s
    others = fleet_rate(r.charge_per_s for r in fleet if r is not robot)
    if others is not None:
        return others
    if robot.drain_per_s is None:
        return None
    return robot.drain_per_s * DEFAULT_CHARGE_PER_DRAIN


def charged_level(
    robot: RobotInfo, level: float, seconds: float, fleet: Iterable[RobotInfo] = ()
) -> float:
    """The level after charging ``seconds`` from ``level`` (up to ``CHARGED``; a level above it
    stays); an unknown rate adds nothing."""
    rate = charge_rate(robot, fleet) or 0.0
    if level >= CHARGED:
        return level
    return min(CHARGED, level + rate * max(0.0, seconds))


def lasts_from(robot: RobotInfo, level: float, wait_s: float, task_s: float) -> bool:
    """From ``level``, at its learned drain, the battery stays above ``battery_low`` for
    ``wait_s`` seconds (else it would be sent to charge first) and then lasts ``task_s`` more
    above the finish floor (charging.py ``can_finish``); an unknown drain: yes."""
    drain = robot.drain_per_s
    if drain is None:
        return True
    wait_s = max(0.0, wait_s)
    if level - drain * wait_s <= robot.config.battery_low:
        return False
    return level - drain * (wait_s + task_s) >= finish_floor(robot)


def latest_charge_start(
    robot: RobotInfo,
    level: float,
    start: float,
    leave: float,
    need: float,
    fleet: Iterable[RobotInfo] = (),
) -> float | None:
    """When, at the latest, a robot at ``level`` at time ``start`` and working on until then
    must start charging so that it has ``need`` when it leaves at ``leave`` (it charges until
    then, up to ``CHARGED``), without falling to ``battery_low`` before (it would then charge
    in full, due to charge); None when no charge from ``start`` gets it there."""
    drain = robot.drain_per_s
    rate = charge_rate(robot, fleet)
    if drain is None or rate is None or need > CHARGED or leave < start:
        return None
    # level - drain * (s - start) + rate * (leave - s) >= need, and above battery_low at s
    by_need = start + (level - need + rate * (leave - start)) / (drain + rate)
    by_low = start + (level - robot.config.battery_low) / drain if drain > 0 else math.inf
    latest = min(by_need, by_low, leave)
    return latest if latest >= start else None


def charge_first_s(
    robot: RobotInfo, level: float, task_s: float, fleet: Iterable[RobotInfo] = ()
) -> float:
    """Seconds a robot at ``level`` charges before it can take a task of ``task_s`` real
    seconds (charging.py ``can_finish``: the Task Manager sends an idle robot short of the
    queued work to a station, and the task takes it off the charger once it lasts the task):
    0 when it lasts it now or its drain is unknown; inf when no charge gets it there."""
    drain = robot.drain_per_s
    if drain is None or not math.isfinite(task_s):
        return 0.0
    need = finish_floor(robot) + drain * task_s
    if level >= need:
        return 0.0
    rate = charge_rate(robot, fleet)
    if need > CHARGED or not rate or rate <= 0:
        return math.inf
    return (need - level) / rate
