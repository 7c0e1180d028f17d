"""Trouble: a door that did not open or a lift that did not come closes itself for a while.

The BuildingInterface answers a robot's ``open_door`` / ``call_elevator`` that failed with
``command_failed`` (addressed to the robot; heard here with a tap). A failure that says the
device did not do it (not open in time, no progress, its module offline) makes the door or
elevator a trouble closure for ``hold_s``: robots re-plan around it while another way
exists. It lifts when the device is seen working (door_opened, the cabin in position with its
door open) or when ``hold_s`` has passed (robots may try it again).

The hold grows with the failures in a row (``hold_for``): nobody sees a door work again while
robots keep off it, so a jam of a few seconds held the door closed for the whole 120 s and tours
skipped every stop behind it. The first failure holds a twelfth of the longest hold (10 s of
the default 120 s), each next one
(the device failed again at its next try, not seen working since) twice as long, up to the
longest hold."""

from __future__ import annotations

from backend.closure import Closure

__all__ = ["FIRST_HOLD_PART", "TROUBLE_HOLD_S", "TROUBLE_WORDS", "hold_for", "trouble_of"]

TROUBLE_HOLD_S = 120.0
"""The longest a failed door or lift stays closed unless seen working before."""

FIRST_HOLD_PART = 12
"""Its first failure (since it was last seen working) closes it for this part of the longest
hold (10 s of 120 s; a soak that scales the longest hold scales this too)."""

TROUBLE_WORDS = ("not open within", "not confirmed", "no progress", "is offline")
"""command_failed reasons that mean the device failed (not a refusal, a bad request or a busy
interface)."""

COMMANDS = {"open_door": "door", "call_elevator": "elevator"}


def hold_for(failures: int, longest_s: float) -> float:
    """The hold of a device's ``failures``-th failure in a row: a ``FIRST_HOLD_PART`` of
    ``longest_s``, doubled with each failure, at most ``longest_s``."""
    first = longest_s / FIRST_HOLD_PART
    return float(min(longest_s, first * 2 ** max(0, min(failures - 1, 16))))


def trouble_of(
    command: str, target: object, reason: str, now: float, hold_s: float
) -> Closure | None:
    """The trouble closure a command_failed means, or None (not the device's fault)."""
    kind = COMMANDS.get(command)
    if kind is None or not isinstance(target, str) or not target:
        return None
    if not any(word in reason for word in TROUBLE_WORDS):
        return None
    what = "did not open" if kind == "door" else "did not come"
    return Closure(
        id=f"trouble-{kind}-{target}",
        kind="door" if kind == "door" else "elevator",
        target=target,
        reason=f"{kind} {target} {what} ({reason})",
        start=now,
        end=now + hold_s,
        by="building",
        source="trouble",
        created_at=now,
    )
