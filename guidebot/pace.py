"""A tour's pace: a visitor may ask for a slower tour (issue 41, docs/accessibility.md).

One place for what "slower" means, read by the server's estimates (backend/tasks/eta.py) and
by the robot that guides (robot_agent/visitor_needs.py), so the time a visitor is told is the
time the robot takes. From the first stop on (the visitor walks with the robot from there, not
before) the robot drives at ``speed`` times its top speed and speaks at 1/``dwell`` of its
rate, so each stop lasts ``dwell`` times as long; the visitor also has ``answer`` times as long
to answer "Shall we continue the tour?" (the tour net's answer times, ``net_params``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

__all__ = ["ANSWER_TIMEOUT_S", "PACES", "PATIENCE_S", "Pace", "PaceName", "net_params", "pace_of"]

PaceName = Literal["normal", "slow"]


@dataclass(frozen=True)
class Pace:
    name: PaceName
    speed: float
    """Factor on the robot's top speed while it walks with its visitor."""
    dwell: float
    """Factor on the time spent explaining at each stop (the speech rate is divided by it)."""
    answer: float
    """Factor on the time the visitor has to answer the robot's "continue?" question."""


PACES: dict[str, Pace] = {
    "normal": Pace("normal", 1.0, 1.0, 1.0),
    "slow": Pace("slow", 0.6, 1.5, 1.5),
}

ANSWER_TIMEOUT_S = 20.0
"""The time a visitor has to answer "Shall we continue the tour?" at the usual pace (the tour
net's ``answer_timeout_s``: the touch screen counts it down)."""
PATIENCE_S = 30.0
"""How long the tour net waits for that answer at all (its ``patience_s``), past the answer
time: the touch screen's own time-out comes first."""


def net_params(pace: Pace) -> dict[str, float]:
    """The tour net's answer times at ``pace``; none at the usual pace (the net's defaults)."""
    if pace.answer == 1.0:
        return {}
    return {
        "answer_timeout_s": ANSWER_TIMEOUT_S * pace.answer,
        "patience_s": PATIENCE_S * pace.answer,
    }


def pace_of(params: Mapping[str, Any] | None) -> Pace:
    """The pace a task's parameters ask for (``pace``; normal when unset or unknown)."""
    name = params.get("pace") if params else None
    return PACES.get(name, PACES["normal"]) if isinstance(name, str) else PACES["normal"]
