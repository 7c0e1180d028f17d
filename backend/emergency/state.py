"""The server's emergency states and the moves allowed between them (docs/emergency.md)."""

from __future__ import annotations

from enum import StrEnum

__all__ = ["TRANSITIONS", "EmergencyError", "EmergencyState", "IllegalMove", "ResumeRefused"]


class EmergencyState(StrEnum):
    normal = "normal"
    alarm = "alarm"
    """An alarm holds one or more zones (from an input or declared by a person)."""
    input_clear = "input_clear"
    """Every alarm input reads normal again; service waits for a person to resume it."""


TRANSITIONS: dict[EmergencyState, frozenset[EmergencyState]] = {
    EmergencyState.normal: frozenset({EmergencyState.alarm}),
    EmergencyState.alarm: frozenset(
        {EmergencyState.alarm, EmergencyState.input_clear, EmergencyState.normal}
    ),
    EmergencyState.input_clear: frozenset({EmergencyState.alarm, EmergencyState.normal}),
}


class EmergencyError(ValueError):
    """A request the emergency service refuses; the text says why (REST 422)."""


class IllegalMove(EmergencyError):
    """A state change the table does not allow (REST 409)."""

    def __init__(self, current: EmergencyState, wanted: EmergencyState) -> None:
        allowed = ", ".join(sorted(TRANSITIONS[current])) or "none"
        super().__init__(
            f"the emergency state is {current.value}; it cannot become {wanted.value}"
            f" (from {current.value}: {allowed})"
        )


class ResumeRefused(EmergencyError):
    """Resume asked while an alarm input still reads alarm, or cannot be read (REST 409)."""
