"""Waits told to visitors stay honest (docs/visitor.md, "The wait"): a robot later than
foretold makes the waits behind it grow instead of sticking at a figure that has run out; a
robot late to its first stop is told on its way with no figure; tours their visitors end early
free their robots early, and the waits behind them count on it; a visit to one point keeps its
"arrived" after it ends; a robot that connects hears the fleet's service (its touch screen says
when staff paused the fleet). Over a bare bus with a hand-moved clock (tests/server/conftest.py)."""

from __future__ import annotations

from backend.tasks import TaskManager
from backend.tasks.model import Task
from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.payloads.site import SiteLoaded

from .conftest import Clock
from .helpers import RobotStub


def told(events: list[Message], task_id: str) -> list[dict[str, object]]:
    return [m.payload for m in events if m.payload["task_id"] == task_id]


def first_leg_s(manager: TaskManager, task: Task, node: str) -> float:
    """Real seconds of the task's leg to its first stop, as the estimator foretells it."""
    seg = manager.estimator.segments(task, node)[0]
    return seg.nominal_s * manager.estimator.move.value


def progress(robot: RobotStub, task: Task, index: int, poi: str, stage: str) -> None:
    robot.endpoint.publish(
        "tour_progress",
        {
            "task_id": task.id,
            "robot": robot.name,
            "index": index,
            "total": 5,
            "poi": poi,
            "stage": stage,
        },
    )


async def test_the_wait_behind_a_late_robot_grows_instead_of_sticking(
    bus: Bus, manager: TaskManager, clock: Clock, events: list[Message]
) -> None:
    """Last session's phone: "about 4 s" for 34 s while the robot ahead was late. What was
    left of the robot's late leg counted as nothing, so the wait stuck at the rest of its
    tour: it now grows with the time the leg takes."""
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    running = manager.request("tour", {"tour": "ground"})
    robot.start(running.id)
    mine = manager.request("tour", {"tour": "highlights"})
    leg = first_leg_s(manager, running, "charge_a")
    waits = []
    for _ in range(4):  # the first leg lasts on, 2, 3, 4, 5 times its forecast
        clock.now += leg
        manager.estimator._schedule = None  # what a simulation built now says
        waits.append(manager.status(mine)["eta_s"])
    assert all(isinstance(w, float) and w > 0 for w in waits), waits
    assert waits == sorted(waits) and waits[0] < waits[-1], waits
    # The news follows it: the visitor is told the longer wait, not left at the old one.
    robot.state("busy")  # still there (a robot silent for 5 s is lost)
    manager.check_timeouts()
    assert told(events, mine.id)[-1]["eta_s"] > told(events, mine.id)[0]["eta_s"]


async def test_a_robot_late_to_the_first_stop_is_on_its_way_without_a_figure(
    bus: Bus, manager: TaskManager, clock: Clock, events: list[Message]
) -> None:
    """Last session: an arrival stuck at "about 6 s" for 56 s. Once the leg to the first stop
    takes longer than foretold, the visitor is told the robot is on its way, with no figure
    (arrival_s null), and told again at the next check."""
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    task = manager.request("tour", {"tour": "ground"})
    robot.start(task.id)
    leg = first_leg_s(manager, task, "charge_a")
    assert manager.status(task)["arrival_s"] == round(leg, 1)
    clock.now += leg / 2
    assert manager.status(task)["arrival_s"] == round(leg / 2, 1)  # counts down as foretold
    clock.now += leg
    late = manager.status(task)
    assert late["arrival_s"] is None and late["service"] == "available"
    assert late["remaining_s"] > 0
    robot.state("busy")
    manager.check_timeouts()
    assert told(events, task.id)[-1]["arrival_s"] is None
    progress(robot, task, 1, "welcome", "arrived")
    assert manager.status(task)["arrival_s"] == 0.0


async def test_tours_their_visitors_end_early_shorten_the_wait_behind_a_tour(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    """Last session: "about 2 min" when the robot started 6-10 s later: the tour ahead ended
    when its visitors said no to "continue?", and every wait counted each tour to its last
    stop. The estimator learns how often visitors go on and counts each later stop by it."""
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()

    def wait_behind_a_new_tour() -> float:
        running = manager.request("tour", {"tour": "ground"})
        robot.start(running.id)
        mine = manager.request("tour", {"tour": "highlights"})
        wait = manager.status(mine)["eta_s"]
        assert isinstance(wait, float)
        manager.cancel(mine.id, reason="measured")
        manager.cancel(running.id, reason="measured")
        robot.end(running.id, "cancelled")
        return wait

    before = wait_behind_a_new_tour()
    for _ in range(4):  # four groups leave after the first stop, each on time
        tour = manager.request("tour", {"tour": "ground"})
        robot.start(tour.id)
        segments = manager.estimator.segments(tour, "charge_a")
        clock.now += segments[0].nominal_s * manager.estimator.move.value
        progress(robot, tour, 1, "welcome", "arrived")
        clock.now += segments[1].nominal_s * manager.estimator.talk.value
        progress(robot, tour, 1, "welcome", "explained")
        robot.end(tour.id, "done")  # "No, thanks"
    after = wait_behind_a_new_tour()
    assert after < 0.8 * before, (before, after)
    assert manager.estimator.go_on.value < 0.7


async def test_a_visit_keeps_its_arrival_after_it_ends(
    bus: Bus, manager: TaskManager, events: list[Message]
) -> None:
    """A visit's "arrived" was dropped at its end (a tour's last progress is kept): the page
    could not say the visit had happened."""
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    visit = manager.request("go_to_poi", {"poi": "mosaics"})
    robot.start(visit.id)
    robot.state("busy", poi="mosaics")
    assert (manager.status(visit)["progress"] or {}).get("stage") == "arrived"
    manager.cancel(visit.id, reason="the visitor left")
    robot.end(visit.id, "cancelled")
    kept = manager.status(visit)["progress"]
    assert kept is not None and kept["index"] == 1 and kept["total"] == 1, kept
    assert kept["poi"] == "mosaics" and kept["stage"] == "arrived"
    assert told(events, visit.id)[-1]["progress"] == kept
    # A visit that never got there has none.
    other = manager.request("go_to_poi", {"poi": "loom"})
    robot.start(other.id)
    manager.cancel(other.id, reason="the visitor left")
    assert manager.status(other)["progress"] is None


async def test_a_robot_that_connects_is_told_the_fleet_is_paused(
    bus: Bus, manager: TaskManager
) -> None:
    """The touch screen showed no sign of staff pausing the fleet: the robot is told the
    service when its link comes up (its site_loaded, sent on every connect), and every change
    after by broadcast."""
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    manager.set_paused(True)
    robot.endpoint.publish(SiteLoaded(robot="R1", version=1))
    told = robot.of_type("visitor_service")
    assert told and told[-1].payload["service"] == "paused"


async def test_a_tours_robot_leading_its_visitors_on_is_told_and_counts_as_a_yes(
    bus: Bus, manager: TaskManager, events: list[Message]
) -> None:
    """The busy demo: "Stop 2 of 3, seen. Next: R3 asks on its screen 'Shall we continue?'"
    for 35 s while the robot was leading its group through the lift. Once the robot is on its
    way after a stop explained, its visitors said yes: the task's progress says it goes on
    (``going``) and the share of visitors who go on learns it."""
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    task = manager.request("tour", {"tour": "ground"})
    robot.start(task.id)
    progress(robot, task, 1, "welcome", "arrived")
    progress(robot, task, 1, "welcome", "explained")
    robot.state("busy", navigation="idle")  # asking "continue?"
    assert "going" not in (manager.status(task)["progress"] or {})
    told_before = len(told(events, task.id))
    robot.state("busy", navigation="moving")
    news = told(events, task.id)
    assert len(news) == told_before + 1, news[told_before:]
    assert news[-1]["progress"]["going"] is True and news[-1]["progress"]["index"] == 1
    assert manager.estimator.go_on.samples == 1 and manager.estimator.go_on.value == 1.0
    robot.state("busy", navigation="moving")  # told once
    assert len(told(events, task.id)) == told_before + 1
    progress(robot, task, 2, "mosaics", "arrived")
    assert "going" not in (manager.status(task)["progress"] or {})
    assert manager.estimator.go_on.samples == 1  # the same yes, not counted twice
