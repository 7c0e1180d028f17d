"""DoorKeeper's answers to an open_door whose holder is dropped (backend/building/doors.py):
also while its coil is still being written, before the request waits for the door."""

from __future__ import annotations

import pytest

from backend.building.doors import DoorKeeper, DoorRefused, DoorReleased
from guidebot.site.building import Door, IORef

DOOR = Door(id="d", node="n", open=IORef(module="m", point="open"), is_open=None)


def keeper() -> DoorKeeper:
    return DoorKeeper(door=DOOR, publish=lambda door, is_open, sensed: None)


async def test_a_refusal_while_the_coil_is_written_is_the_answer_of_the_wait() -> None:
    """The fire alarm drops R1 (evacuating) and R2 (outside its zone) between their hold and
    their wait (CI: R2's Modbus write was still under way): R2 is refused with the alarm's
    reason when it comes to wait, R1 withdrawn; it used to be withdrawn silently, unanswered."""
    door = keeper()
    door.hold("R1", lambda: None)
    door.hold("R2", lambda: None)
    door.release_all(withdraw="the alarm dropped its holders", refuse="fire alarm", spare={"R1"})
    with pytest.raises(DoorRefused, match="fire alarm"):
        await door.wait_open(5.0, "R2")
    with pytest.raises(DoorReleased, match="the alarm dropped its holders"):
        await door.wait_open(5.0, "R1")


async def test_a_holder_that_asks_again_after_a_refusal_is_not_refused_by_the_old_one() -> None:
    door = keeper()
    door.hold("R2", lambda: None)
    door.release_all(refuse="fire alarm")
    door.hold("R2", lambda: None)  # its next open_door, once the alarm is over
    door.state(True)
    await door.wait_open(5.0, "R2")  # open: no old refusal raised
