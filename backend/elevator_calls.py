"""Which elevator calls go into the event log. A robot presses the call again and again, as a
person keeps the button pressed: while it waits (the call is already set) and while it drives
in or out (to keep the door open). Logging every press filled the event log with a row every
two seconds per robot, and a press at a floor where the cabin already stood open started an
elevator wait in the reports that only the cabin's next arrival, minutes later, ended. So a
call is logged when it is news: its floor not yet called, the cabin not standing open there."""

from __future__ import annotations

from guidebot.payloads.building import CabinState, ElevatorState

__all__ = ["CallNews"]


class CallNews:
    """Fed every ``elevator_state``; says whether a ``call_elevator`` is worth a log row."""

    def __init__(self) -> None:
        self._cabins: dict[str, ElevatorState] = {}

    def cabin(self, state: ElevatorState) -> None:
        self._cabins[state.elevator] = state

    def is_news(self, elevator: str, floor: str) -> bool:
        cabin = self._cabins.get(elevator)
        if cabin is None:
            return True
        standing_open = (
            cabin.floor == floor and cabin.door_open and cabin.state is not CabinState.moving
        )
        return not standing_open and floor not in cabin.calls
