"""The estimates in task_event payloads are never stale: what is left of a running tour
follows the learned factors and the clock, and a queued task's wait follows the queue (the
estimator keeps sums and a cached simulation to make these cheap; docs/visitor.md "The wait")."""

from __future__ import annotations

from backend.tasks import TaskManager
from guidebot.bus import Bus
from guidebot.messages import Message

from .conftest import Clock
from .helpers import RobotStub


def last_event(events: list[Message], task_id: str) -> dict[str, object]:
    return [m.payload for m in events if m.payload["task_id"] == task_id][-1]


def real_s(manager: TaskManager, nominal: list[tuple[str, float]]) -> float:
    est = manager.estimator
    return sum(s * (est.move.value if kind == "move" else est.talk.value) for kind, s in nominal)


async def test_a_running_tour_is_told_what_is_left_with_the_factors_learned_since(
    bus: Bus, manager: TaskManager, clock: Clock, events: list[Message]
) -> None:
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    task = manager.request("tour", {"tour": "ground"})
    robot.start(task.id)
    segments = [(s.kind, s.nominal_s) for s in manager.estimator.segments(task, "charge_a")]
    started = last_event(events, task.id)
    assert started["duration_s"] == round(real_s(manager, segments[1:]), 1)
    assert started["remaining_s"] == round(real_s(manager, segments), 1)
    # The first leg takes three times its prediction: legs are learned slower.
    clock.now += 3 * segments[0][1]
    robot.endpoint.publish(
        "tour_progress",
        {
            "task_id": task.id,
            "robot": "R1",
            "index": 1,
            "total": 5,
            "poi": "welcome",
            "stage": "arrived",
        },
    )
    assert manager.estimator.move.value > 2.5
    arrived = last_event(events, task.id)
    assert arrived["duration_s"] == round(real_s(manager, segments[1:]), 1)
    assert arrived["remaining_s"] == round(real_s(manager, segments[1:]), 1)
    assert arrived["arrival_s"] == 0.0
    # Time passes inside the explanation: it counts down, the legs after it do not.
    clock.now += 2.0
    status = manager.status(task)
    talk = real_s(manager, segments[1:2])
    assert status["remaining_s"] == round(max(0.0, talk - 2.0) + real_s(manager, segments[2:]), 1)


async def test_a_request_ahead_of_others_is_told_the_wait_a_new_simulation_gives(
    bus: Bus, manager: TaskManager
) -> None:
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    robot.start(manager.request("tour", {"tour": "ground"}).id)
    for k in range(300):  # past a few checkpoints of the cached simulation
        manager.request("go_to_poi", {"poi": "mosaics"}, priority=5 if k % 2 else 3)
    manager.status(manager.queue.ordered().__next__())  # the simulation is built
    ahead = manager.request("tour", {"tour": "upstairs"}, priority=4)  # 151st of 301
    middle = manager.request("go_to_poi", {"poi": "loom"}, priority=3)  # behind the 300
    first = manager.request("tour", {"tour": "highlights"}, priority=9)
    told = {t.id: manager.eta_s(t) for t in (ahead, middle, first)}
    manager.estimator._schedule = None  # what a simulation built now says
    assert told == {t.id: manager.eta_s(t) for t in (ahead, middle, first)}
    assert told[first.id] < told[ahead.id] < told[middle.id]


async def test_a_queued_wait_follows_the_queue_at_once(bus: Bus, manager: TaskManager) -> None:
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    robot.start(manager.request("tour", {"tour": "ground"}).id)
    before = manager.request("tour", {"tour": "upstairs"})
    behind = manager.request("tour", {"tour": "highlights"})
    wait_before, wait_behind = manager.eta_s(before), manager.eta_s(behind)
    assert wait_before is not None and wait_behind is not None and wait_behind > wait_before
    manager.cancel(before.id)
    # No longer behind the cancelled tour: it waits for the running one only.
    assert manager.eta_s(behind) == wait_before


async def test_a_skipped_stop_leaves_its_leg_and_talk_out_and_is_told_with_its_reason(
    bus: Bus, manager: TaskManager, clock: Clock, events: list[Message]
) -> None:
    """Issue 36: a stop only closed elements lead to is skipped; what is left no longer counts
    it (and nothing is learned from it), and the task's progress names it with why."""
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    task = manager.request("tour", {"tour": "ground"})
    robot.start(task.id)
    segments = [(s.kind, s.nominal_s) for s in manager.estimator.segments(task, "charge_a")]
    move, talk = manager.estimator.move.value, manager.estimator.talk.value
    clock.now += 1.0
    robot.endpoint.publish(
        "tour_progress",
        {
            "task_id": task.id,
            "robot": "R1",
            "index": 1,
            "total": 5,
            "poi": "welcome",
            "stage": "skipped",
            "reason": "gallery hall closed: a reception",
        },
    )
    assert (manager.estimator.move.value, manager.estimator.talk.value) == (move, talk)
    skipped = last_event(events, task.id)
    assert skipped["remaining_s"] == round(real_s(manager, segments[2:]), 1)
    progress = skipped["progress"]
    assert isinstance(progress, dict)
    assert progress["skipped"] == [
        {
            "index": 1,
            "poi": "welcome",
            "name": "Welcome hall",
            "reason": "gallery hall closed: a reception",
        }
    ]


async def test_a_queued_tour_is_told_its_length_without_the_stops_closed_now(
    manager: TaskManager,
) -> None:
    """Building modes: a closed gallery's stops will be skipped, so a tour asked for now is
    told a shorter length; once reopened, the whole tour again."""
    whole = manager.estimator.preview("tour", {"tour": "ground"}).duration_s
    assert whole is not None
    manager.estimator.closed = lambda: {"gb1": "closed", "gb2": "closed"}
    shorter = manager.estimator.preview("tour", {"tour": "ground"}).duration_s
    assert shorter is not None and shorter < whole
    manager.estimator.closed = lambda: {}
    assert manager.estimator.preview("tour", {"tour": "ground"}).duration_s == whole


async def test_a_queued_tour_is_told_its_length_without_the_stops_cut_off_behind_a_closure(
    manager: TaskManager,
) -> None:
    """Issue 36: a closed corridor node cuts off the sword (gb1) and the loom (gb2): the
    back gallery's way round is one-way from there. The tour will skip both, so a tour asked
    for now is told the same length as with their own nodes closed."""
    whole = manager.estimator.preview("tour", {"tour": "ground"}).duration_s
    manager.estimator.closed = lambda: {"gb1": "closed", "gb2": "closed"}
    without = manager.estimator.preview("tour", {"tour": "ground"}).duration_s
    manager.estimator.closed = lambda: {"corridor_w": "closed"}
    behind = manager.estimator.preview("tour", {"tour": "ground"}).duration_s
    assert whole is not None and without is not None and without < whole
    assert behind == without
