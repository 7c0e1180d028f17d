"""What is learned of a robot's battery rates, and what stands in (docs/server.md, "Charging"):
a change of level that no work explains is not learned as a rate, and until a robot has learned
a rate, the fleet's (the median of the other robots' learned ones) stands in. The drain is
learned in charging.py (``learn_drain``), the charge rate in battery_forecast.py
(``learn_charge``).

A jump: the soak's ``battery_panic`` fault sets a robot's simulated level to 5 % at once; learned
as drain (0.9 to 0.05 in one 5 s span: a hundred times the real drain) it kept the robot from
every tour and booking (``can_finish``) for as long as the running average took to forget it,
and an idle robot, whose level does not fall, never forgot it."""

from __future__ import annotations

import statistics
from collections.abc import Iterable

__all__ = [
    "JUMP_FACTOR",
    "JUMP_SLACK",
    "UNKNOWN_JUMP",
    "UNKNOWN_JUMP_WITHIN_S",
    "fleet_rate",
    "is_jump",
]

JUMP_FACTOR = 5.0
"""A change of level over a span of readings more than this many times what the known rate
explains (a robot moving drains about four times what it drains standing: the simulated one)..."""
JUMP_SLACK = 0.02
"""... plus this much (levels are coarse, a reading may come late) is a jump, not a rate."""
UNKNOWN_JUMP = 0.10
UNKNOWN_JUMP_WITHIN_S = 30.0
"""With no rate known yet, the robot's nor its fleet's: a change of more than ``UNKNOWN_JUMP``
within ``UNKNOWN_JUMP_WITHIN_S`` is a jump (at the soak's time scale 10 the simulated robot
drains 0.7 % in 5 s moving)."""


def is_jump(change: float, span_s: float, rate: float | None) -> bool:
    """A change of level (its size) over ``span_s`` seconds that ``rate`` (the robot's learned
    one, else its fleet's; None: neither is known) does not explain: a fault, a battery
    swapped, a reading gone wrong. It teaches nothing; the next span starts from it."""
    if rate is None:
        return change > UNKNOWN_JUMP and span_s < UNKNOWN_JUMP_WITHIN_S
    return change > JUMP_FACTOR * rate * span_s + JUMP_SLACK


def fleet_rate(learned: Iterable[float | None]) -> float | None:
    """The median of the rates the other robots of the fleet have learned (None: none has)."""
    known = [r for r in learned if r is not None]
    return statistics.median(known) if known else None
