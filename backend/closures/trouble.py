"""Trouble: a door that did not open or a lift that did not come closes itself for a while.

The BuildingInterface answers a robot's ``open_door`` / ``call_elevator`` that failed with
``command_failed`` (addressed to the robot; heard here with a tap). A failure that says the
device did not do it (not open in time, no progress, its module offline) makes the door or
elevator a trouble closure for ``hold_s``: robots re-plan around it while another way
exists. It lifts when the device is seen working (door_opened, the cabin in position with its
door open) or when ``hold_s`` has passed (robots may try it again)."""

from __future__ import annotations

from backend.closure import Closure

__all__ = ["TROUBLE_HOLD_S", "TROUBLE_WORDS", "trouble_of"]

TROUBLE_HOLD_S = 120.0
"""How long a failed door or lift stays closed unless seen working before."""

TROUBLE_WORDS = ("not open within", "not confirmed", "no progress", "is offline")
"""command_failed reasons that mean the device failed (not a refusal, a bad request or a busy
interface)."""

COMMANDS = {"open_door": "door", "call_elevator": "elevator"}


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
