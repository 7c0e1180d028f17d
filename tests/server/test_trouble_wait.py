"""A visitor's task cut off only by trouble waits for it in the queue instead of failing
(backend/tasks/trouble.py; issue 36: in the fault soak 12 of 106 visits failed "elevator lift
out of order" while each jam lasted seconds). Task Manager and closures over a real bus."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from backend.closures.service import ClosureService
from backend.tasks import TaskManager, TaskState
from backend.tasks.trouble import MAX_WAITS
from guidebot.bus import Bus

from .helpers import RobotStub, demo_site

STUCK = "call not confirmed: the cabin showed no progress for 14 s"
FAILED = "navigation to gc1 failed: elevator lift out of order"


@pytest.fixture
async def closures(bus: Bus, manager: TaskManager) -> AsyncIterator[ClosureService]:
    site = demo_site()
    service = ClosureService(bus.endpoint("closures"), lambda: site, None, None)
    manager.estimator.closed = lambda: service.closed
    await service.start()
    yield service
    await service.stop()


def lift_fails(bus: Bus, robot: str, attempt: int = 1) -> None:
    failed = {"command": "call_elevator", "reason": STUCK, "target": "lift"}
    bus.endpoint(f"building-{attempt}").publish("command_failed", failed, destination=robot)


async def test_a_visit_cut_off_by_a_stuck_lift_waits_for_it_and_is_given_out_again(
    bus: Bus, manager: TaskManager, closures: ClosureService
) -> None:
    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    visit = manager.request("go_to_poi", {"poi": "tapestries"})
    await r1.wait_for("task_assigned")
    r1.start(visit.id)
    lift_fails(bus, "R1")
    assert "lift0" in closures.closed
    r1.end(visit.id, "failed", FAILED, trouble=True)
    assert visit.state is TaskState.QUEUED
    assert "waiting for elevator lift to work again" in visit.reason
    told = {"why": "elevator lift out of order", "wait": 1, "waits": MAX_WAITS}
    assert manager.status(visit)["trouble"] == told  # what its visitor is told
    assert manager.event(visit).trouble == told
    r1.state()
    manager.dispatch()
    assert visit.state is TaskState.QUEUED  # not given out while the lift is out
    given = len(r1.of_type("task_assigned"))
    bus.endpoint("lift-sensor").publish(
        "elevator_in_position", {"elevator": "lift", "floor": "F0", "door_open": True}
    )
    assert not closures.closed  # closures_changed: given out again at once
    again = await r1.wait_for("task_assigned", given + 1)
    assert again.payload["task_id"] == visit.id
    assert manager.status(visit)["trouble"] is None
    r1.start(visit.id)
    r1.end(visit.id)
    assert visit.state is TaskState.DONE


async def test_a_visit_behind_a_lift_that_stays_broken_fails_after_a_few_waits(
    bus: Bus, manager: TaskManager, closures: ClosureService
) -> None:
    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    visit = manager.request("go_to_poi", {"poi": "tapestries"})
    for attempt in range(1, MAX_WAITS + 2):
        await r1.wait_for("task_assigned", len(r1.of_type("task_assigned")) or 1)
        assert visit.state is TaskState.ASSIGNED
        r1.start(visit.id)
        lift_fails(bus, "R1", attempt)
        r1.end(visit.id, "failed", FAILED, trouble=True)
        if attempt <= MAX_WAITS:
            assert visit.state is TaskState.QUEUED
            closures.closures.clear()  # its hold over; broken again at the next try
            closures.refresh(force=True)
            r1.state()
            manager.dispatch()
    assert visit.state is TaskState.FAILED and visit.reason == FAILED


async def test_a_visit_cut_off_by_a_closure_of_staff_fails_at_once(
    bus: Bus, manager: TaskManager, closures: ClosureService
) -> None:
    from backend.closure import ClosureRequest

    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    visit = manager.request("go_to_poi", {"poi": "tapestries"})
    await r1.wait_for("task_assigned")
    r1.start(visit.id)
    await closures.add(ClosureRequest(kind="elevator", target="lift", reason="service"), by="ann")
    r1.end(visit.id, "failed", "navigation to gc1 failed: elevator lift closed: service", False)
    assert visit.state is TaskState.FAILED


@pytest.mark.parametrize(
    ("reason", "trouble"),
    [
        ("navigation to gc1 failed: bumper pressed for too long", False),
        # Words of trouble in another cause's reason: the server read the text, and queued it.
        ("robot fault motor_lost: wheel driver out of order", False),
        # An older robot that sends no flag: its failure stands.
        (FAILED, None),
    ],
)
async def test_a_visit_that_failed_for_another_cause_fails_even_while_trouble_cuts_its_way(
    bus: Bus, manager: TaskManager, closures: ClosureService, reason: str, trouble: bool | None
) -> None:
    """The robot's typed flag decides, not its words: a motor fault during a lift jam is not
    the jam's doing, whatever its text says."""
    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    visit = manager.request("go_to_poi", {"poi": "tapestries"})
    await r1.wait_for("task_assigned")
    r1.start(visit.id)
    lift_fails(bus, "R1")
    assert "lift0" in closures.closed
    r1.end(visit.id, "failed", reason, trouble)
    assert visit.state is TaskState.FAILED and visit.reason == reason


async def test_a_visit_its_robot_says_trouble_cut_off_waits_whatever_the_words(
    bus: Bus, manager: TaskManager, closures: ClosureService
) -> None:
    """The reason is words for people (the closures' own, maybe in another language): the
    server looked for "out of order" in it and failed a visit the robot had said trouble cut
    off. The typed flag, then the map, decide."""
    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    visit = manager.request("go_to_poi", {"poi": "tapestries"})
    await r1.wait_for("task_assigned")
    r1.start(visit.id)
    lift_fails(bus, "R1")
    r1.end(visit.id, "failed", "navigation to gc1 failed: ascensor lift fuera de servicio", True)
    assert visit.state is TaskState.QUEUED
    assert "waiting for elevator lift to work again" in visit.reason
