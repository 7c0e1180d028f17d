"""Live waits (backend/tasks/news.py): a queued task's place in line and wait are told again
when they move without the task changing, a drift from the told countdown is told, a jam (a
held-up robot) promises no wait, and what a new request would be told goes out as
``visitor_service`` (docs/visitor.md, "Live waits")."""

from __future__ import annotations

from backend.tasks import TaskManager
from backend.tasks.news import QUIET_EVERY_S
from backend.tasks.presence import HELD_UP_AFTER_S
from guidebot.bus import Bus
from guidebot.messages import Message

from .conftest import Clock
from .helpers import RobotStub


def told(events: list[Message], task_id: str) -> list[dict[str, object]]:
    return [m.payload for m in events if m.payload["task_id"] == task_id]


async def test_a_place_in_line_is_told_again_when_the_line_moves(
    bus: Bus, manager: TaskManager, clock: Clock, events: list[Message]
) -> None:
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    running = manager.request("tour", {"tour": "ground"})
    robot.start(running.id)
    ahead = manager.request("go_to_poi", {"poi": "mosaics"})
    mine = manager.request("tour", {"tour": "highlights"})
    assert told(events, mine.id)[-1]["queue_position"] == 2
    manager.check_timeouts()  # nothing moved: nothing told again
    assert len(told(events, mine.id)) == 1
    manager.cancel(ahead.id, reason="not needed")
    clock.now += 1.0
    manager.check_timeouts()
    now = told(events, mine.id)
    assert len(now) == 2 and now[-1]["queue_position"] == 1 and now[-1]["state"] == "queued"
    assert now[-1]["eta_s"] == manager.status(mine)["eta_s"]


async def test_a_wait_is_told_again_only_when_it_drifts_from_its_countdown(
    bus: Bus, manager: TaskManager, clock: Clock, events: list[Message]
) -> None:
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    running = manager.request("tour", {"tour": "ground"})
    robot.start(running.id)
    mine = manager.request("tour", {"tour": "highlights"})
    first = told(events, mine.id)[-1]["eta_s"]
    assert isinstance(first, float)
    # The running tour goes as foretold: the wait counts down as the page counts it.
    clock.now += QUIET_EVERY_S
    manager.check_timeouts()
    assert len(told(events, mine.id)) == 1
    # The robot is far slower than foretold: its first leg lasts on, the wait drifts up.
    clock.now += first
    manager.check_timeouts()
    assert len(told(events, mine.id)) == 2


async def test_a_jam_promises_no_wait_and_says_so(
    bus: Bus, manager: TaskManager, clock: Clock, events: list[Message]
) -> None:
    service: list[Message] = []
    bus.endpoint("panel").subscribe("visitor_service", service.append)
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    running = manager.request("go_to_poi", {"poi": "mosaics"})
    robot.start(running.id)
    mine = manager.request("tour", {"tour": "highlights"})
    clock.now += QUIET_EVERY_S
    manager.check_timeouts()
    assert manager.status(mine)["service"] == "busy"
    # Stopped before a door that does not open.
    robot.state("busy", navigation="door_blocked")
    assert manager.estimator.service() == "held_up"
    clock.now += 1.0
    manager.check_timeouts()
    now = told(events, mine.id)[-1]
    assert now["service"] == "held_up" and now["eta_s"] is None
    assert told(events, running.id)[-1]["service"] == "held_up"
    assert service[-1].payload == {"service": "held_up", "eta_s": None}
    assert manager.estimator.preview("tour", {"tour": "ground"}).service == "held_up"
    # The door opens: it moves on, and waits are promised again.
    robot.state("busy", navigation="moving")
    clock.now += 1.0
    manager.check_timeouts()
    assert told(events, mine.id)[-1]["service"] == "busy"
    assert service[-1].payload["service"] == "busy"


async def test_a_robot_waiting_long_for_an_area_is_held_up(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    robot.start(manager.request("go_to_poi", {"poi": "mosaics"}).id)
    robot.state("busy", navigation="waiting_area")
    clock.now += HELD_UP_AFTER_S - 1
    robot.state("busy", navigation="waiting_area")
    assert not manager.robots["R1"].held_up
    clock.now += 1
    robot.state("busy", navigation="waiting_area")
    assert manager.robots["R1"].held_up
    robot.state("busy", navigation="moving")
    assert not manager.robots["R1"].held_up


async def test_a_pause_before_the_first_check_is_told(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    """Staff paused the fleet before the news' first check (a server just started): that check
    only took what it found as its baseline, and the robots' touch screens, told the service
    when they connected, never heard of the pause (CI, tests/web/test_visitor_truths.py)."""
    service: list[Message] = []
    bus.endpoint("panel").subscribe("visitor_service", service.append)
    RobotStub(bus, "R1", "charge_a").state()
    manager.set_paused(True)
    clock.now += QUIET_EVERY_S
    manager.check_timeouts()
    assert service and service[-1].payload["service"] == "paused"
