"""The emergency states' transition table: an illegal move says what was expected."""

from __future__ import annotations

import pytest

from backend.emergency.state import TRANSITIONS, EmergencyState, IllegalMove


def test_every_state_has_its_moves_and_normal_only_goes_to_alarm() -> None:
    assert set(TRANSITIONS) == set(EmergencyState)
    assert TRANSITIONS[EmergencyState.normal] == {EmergencyState.alarm}
    assert EmergencyState.normal in TRANSITIONS[EmergencyState.input_clear]


def test_an_illegal_move_names_the_state_and_the_moves_allowed() -> None:
    with pytest.raises(IllegalMove) as info:
        raise IllegalMove(EmergencyState.normal, EmergencyState.input_clear)
    assert str(info.value) == (
        "the emergency state is normal; it cannot become input_clear (from normal: alarm)"
    )
