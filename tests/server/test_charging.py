"""Charging and elevator-aware waits in the Task Manager (issue 36), over a real bus with
scripted robots: staff send a robot to charge, a charging robot is not given a tour it cannot
finish, touring time is counted for turns, and a wait foretold across floors counts the lift's
queue."""

from __future__ import annotations

from backend.alerts import AlertStore
from backend.tasks import Task, TaskManager, TaskState
from backend.tasks.blocked import FIRST_BACKOFF_S
from guidebot.bus import Bus
from guidebot.messages import Message

from .conftest import Clock
from .helpers import RobotStub


async def given(robot: RobotStub, task_id: str) -> Message:
    """The task_assigned of ``task_id`` to ``robot`` (idle errands may come before it)."""
    for count in range(1, 10):
        msg = await robot.wait_for("task_assigned", count)
        if msg.payload["task_id"] == task_id:
            return msg
    raise AssertionError(f"{task_id} never assigned to {robot.name}")


async def test_staff_send_a_robot_to_charge_at_the_nearest_free_station_after_its_tour(
    bus: Bus, manager: TaskManager
) -> None:
    r1 = RobotStub(bus, "R1", "charge_a")  # stands on station_a
    manager.robots["R2"].node = "entrance"  # (offline) off station_b, where the site starts it
    r3 = RobotStub(bus, "R3", "hall")
    r1.state()
    r3.state()
    tour = manager.request("tour", {"tour": "ground"})
    await given(r3, tour.id)
    r3.start(tour.id)
    charge = manager.send_to_charge("R3", by="desk")
    assert charge.params == {"station": "station_b"}  # station_a is R1's: the free one
    assert charge.pinned_robot == "R3" and charge.state is TaskState.QUEUED  # after its tour
    r3.end(tour.id)
    order = await given(r3, charge.id)
    assert order.payload["net"] == "battery_charge"
    # A robot standing on a station charges there.
    assert manager.send_to_charge("R1", by="desk").params == {"station": "station_a"}


async def test_a_charging_robot_is_not_given_a_tour_it_cannot_finish(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    probe = Task("p", "tour", {"tour": "ground"}, 5, "", 0)
    visit = Task("v", "go_to_poi", {"poi": "welcome"}, 5, "", 0)
    tour_s = manager.estimator.task_s(probe, "charge_a")
    visit_s = manager.estimator.task_s(visit, "charge_a")
    assert visit_s < tour_s / 2
    # It drains 0.2 (its level 0.4 down to the finish floor) in the time of a third of a tour.
    drain = 0.2 / (tour_s / 3)
    r1 = RobotStub(bus, "R1", "hall", battery=0.4 + drain * 100)
    r1.state("busy")
    clock.now += 100
    r1.battery = 0.4
    r1.state("busy")
    assert abs((manager.robots["R1"].drain_per_s or 0) - drain) < 1e-9
    # Now charging at its station (an internal task a tour may preempt) at 0.4.
    r1.node = "charge_a"
    r1.state("charging")
    tour = manager.request("tour", {"tour": "ground"})
    assert tour.state is TaskState.QUEUED  # it would end the tour far below the floor
    r2 = RobotStub(bus, "R2", "charge_b")
    r2.state()
    await given(r2, tour.id)
    short = manager.request("go_to_poi", {"poi": "welcome"})
    await given(r1, short.id)  # a short visit it can finish


async def test_the_charge_rate_is_learned_from_rising_readings_whatever_the_mode_says(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    """The soak's robots say ``busy`` on their charge task while they fill: the rate the
    bookings plan a charge ahead with (backend/tasks/battery_forecast.py) is learned from
    the rising readings, not from the mode; readings too close, a fall, or a full battery
    teach nothing."""
    r1 = RobotStub(bus, "R1", "charge_a", battery=0.40)
    robot = manager.robots["R1"]
    # (seconds after the first reading, level, mode): 0.41 two seconds on is too close to tell
    for at, level, mode in ((0, 0.40, "busy"), (2, 0.41, "busy"), (10, 0.43, "charging")):
        clock.now = 1000.0 + at
        r1.battery = level
        r1.state(mode)
    clock.now += 10
    r1.battery = 0.46
    r1.state("busy")
    assert robot.charge_per_s is not None and abs(robot.charge_per_s - 0.003) < 1e-9
    r1.battery = 0.46  # off the charger: falling, a new start
    r1.state("busy")
    clock.now += 10
    r1.battery = 0.96  # full (a reading after a long gap): nothing learned
    r1.state("idle")
    assert abs(robot.charge_per_s - 0.003) < 1e-9


async def test_touring_time_is_counted_per_robot(bus: Bus, manager: TaskManager) -> None:
    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    task = manager.request("go_to_poi", {"poi": "welcome"})
    await r1.wait_for("task_assigned")
    r1.start(task.id)
    r1.end(task.id)
    assert manager.robots["R1"].touring_s > 0
    assert manager.robots["R1"].as_dict()["touring_s"] >= 0


async def test_a_wait_across_floors_counts_the_lift_queue(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    upstairs = next(n.id for n in manager.site.nodes if n.floor != "F0")
    empty = manager.estimator.preview("go_to_poi", {"poi": "welcome"})
    assert empty.arrival_s is None  # no robot online yet
    r1 = RobotStub(bus, "R1", upstairs)
    r1.state()
    alone = manager.estimator.preview("go_to_poi", {"poi": "welcome"})
    manager.lifts.queue = lambda: 4  # four robots hold or wait for the lift
    clock.now += 2  # the queue is read again, the foretold line rebuilt
    queued = manager.estimator.preview("go_to_poi", {"poi": "welcome"})
    assert alone.arrival_s is not None and queued.arrival_s is not None
    assert queued.arrival_s >= alone.arrival_s + 4 * manager.lifts.turn_s - 1
    assert manager.lift_wait_s(upstairs, "hall") == 4 * manager.lifts.turn_s
    assert manager.lift_wait_s("entrance", "hall") == 0.0


def must_charge(bus: Bus, manager: TaskManager) -> tuple[AlertStore, RobotStub]:
    """The manager's alerts, and R1 at the hall with its battery low: it must charge (R2,
    offline, off the station where the site starts it)."""
    alerts = AlertStore(bus.endpoint("alerts").publish)
    manager.alerts = alerts
    manager.robots["R2"].node = "entrance"
    r1 = RobotStub(bus, "R1", "hall", battery=0.25)
    r1.state()
    r1.endpoint.publish("battery_low", {"robot": "R1", "level": 0.25})
    return alerts, r1


async def test_a_charge_that_fails_at_once_is_not_made_again_before_a_back_off(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    """A robot whose way to every station fails for a reason the server does not see (no
    closure explains it) tries each station once, then again after a back-off of seconds,
    not at once (the fault soak's loop: backend/tasks/blocked.py); staff get one alert."""
    alerts, r1 = must_charge(bus, manager)
    stations = []
    for n in (1, 2):
        order = (await r1.wait_for("task_assigned", n)).payload
        assert order["net"] == "battery_charge"
        stations.append(manager.tasks[order["task_id"]].params["station"])
        r1.start(order["task_id"])
        r1.end(order["task_id"], "failed", "navigation failed: the base refused the path")
    assert sorted(stations) == ["station_a", "station_b"]  # each once
    for _ in range(3):
        r1.state()
        manager.check_timeouts()
    assert len(r1.of_type("task_assigned")) == 2
    [alert] = alerts.active()
    assert alert.kind == "charge_unreachable" and alert.subject == "R1"
    # Said from the typed fields (the errand's kind, no trouble flag), not the robot's text.
    assert "cannot reach a charging station: its charge at charge_" in alert.message
    assert "failed (no closure cuts its way off)" in alert.message
    assert "the base refused" not in alert.message
    clock.now += FIRST_BACKOFF_S
    r1.state()
    manager.check_timeouts()
    again = (await r1.wait_for("task_assigned", 3)).payload
    assert manager.tasks[again["task_id"]].params["station"] == stations[0]
    r1.start(again["task_id"])
    r1.node = "charge_a" if stations[0] == "station_a" else "charge_b"
    r1.state("busy")  # it got there: the alert is resolved
    assert not alerts.active()


async def test_an_errands_failure_is_described_from_its_typed_fields_not_the_robots_words(
    bus: Bus, manager: TaskManager
) -> None:
    """The robot's reason is words for people: "door D0 out of order" from a robot whose
    way no closure cuts off (and an older robot's, or another cause's, words) made staff's
    alert name a door that was not the cause. The bar says what failed from the errand's
    kind and the robot's ``trouble`` flag (trouble that has lifted since it failed)."""
    alerts, r1 = must_charge(bus, manager)
    for n in (1, 2):
        order = (await r1.wait_for("task_assigned", n)).payload
        r1.start(order["task_id"])
        r1.end(order["task_id"], "failed", "navigation failed: door D0 out of order", trouble=True)
    [alert] = alerts.active()
    assert alert.kind == "charge_unreachable"
    assert "trouble cut off its charge at charge_" in alert.message, alert.message
    assert "D0" not in alert.message


async def test_a_battery_fault_is_not_learned_as_drain(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    """The soak's ``battery_panic`` fault sets a robot's level to 5 % at once. Learned as drain
    (0.83 in 5 s), it kept the robot from every tour long after it had charged back (and an
    idle robot, whose level does not fall, never forgot it). A fall its learned drain does not
    explain teaches nothing; nor does one the fleet's drain does not explain, for a robot that
    has learned none yet; nor a rise its charge rate does not explain."""
    r1 = RobotStub(bus, "R1", "hall", battery=0.90)
    robot = manager.robots["R1"]
    for level in (0.90, 0.89, 0.88):  # 0.001 a second on its way
        r1.battery = level
        r1.state("busy")
        clock.now += 10
    assert robot.drain_per_s is not None and abs(robot.drain_per_s - 0.001) < 1e-9
    r1.battery = 0.05  # the fault
    r1.state("busy")
    r1.endpoint.publish("battery_panic", {"robot": "R1", "level": 0.05})
    clock.now += 5
    r1.state("busy")
    assert abs(robot.drain_per_s - 0.001) < 1e-9

    r3 = RobotStub(bus, "R3", "entrance", battery=0.90)  # no drain of its own yet
    r3.state("idle")
    clock.now += 5
    r3.battery = 0.30  # ... set low at once: R1's drain does not explain it
    r3.state("idle")
    assert manager.robots["R3"].drain_per_s is None

    # R1 charges back (a rise of 0.45 in 5 s is no charger either: not learned) ...
    r1.node = "charge_a"
    for step, level in enumerate((0.05, 0.10, 0.55, 0.60, 0.65, 0.95)):
        clock.now += 5 if step == 2 else 50
        r1.battery = level
        r1.state("charging")
    assert robot.charge_per_s is not None and abs(robot.charge_per_s - 0.001) < 1e-9
    assert not robot.needs_charge
    # ... and takes a tour it can finish at its real drain.
    tour = manager.request("tour", {"tour": "ground"})
    assert tour.robot == "R1"


async def test_an_idle_robot_short_of_the_queued_tour_charges_then_takes_it(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    """An idle robot above ``battery_low`` whose battery would not last the queued tour
    counted as having work: it stood at its wait point (at 85 %, above where a robot at a
    wait point charges on its own), the tour waiting, for ever, and the visitor was told a
    robot was free. It goes to charge; the visitor's wait counts the charge; the tour takes
    it off the charger once its battery lasts the tour."""
    for name in ("R1", "R2"):  # offline, and off the stations the site starts them on
        manager.robots[name].node = "hall"
    probe = Task("p", "tour", {"tour": "ground"}, 5, "", 0)
    tour_s = manager.estimator.task_s(probe, "entrance")
    drain = 0.68 / tour_s  # 85 % would leave 17 %: under the finish floor (20 %)
    slow = drain / 10
    manager.robots["R1"].charge_per_s = slow  # learned on its charger: R3 has not charged yet
    r3 = RobotStub(bus, "R3", "entrance", battery=0.85 + drain * 10)
    r3.state("busy")
    clock.now += 10
    r3.battery = 0.85
    r3.state("idle")
    robot = manager.robots["R3"]
    assert robot.drain_per_s is not None and abs(robot.drain_per_s - drain) < 1e-9

    tour = manager.request("tour", {"tour": "ground"})
    assert tour.state is TaskState.QUEUED
    charge = manager.current_of(robot)
    assert charge is not None and charge.kind == "charge"
    clock.now += 2  # the foretold line is built again
    told = manager.estimator.estimate(tour)
    # It charges from 85 % to what the tour takes above the floor, at the rate R1 learned.
    charge_s = (0.2 + drain * tour_s - 0.85) / slow
    assert told.service == "busy" and told.wait_s is not None
    assert abs(told.wait_s - charge_s) < 1.0, (told.wait_s, charge_s)

    r3.start(charge.id)
    station = next(s for s in manager.site.charging_stations if s.id == charge.params["station"])
    r3.node = station.node
    there_s = manager.estimator.task_s(probe, station.node)
    enough = 0.2 + drain * there_s
    assert enough < 0.94
    for level in (0.85, enough - 0.01, enough + 0.01):
        clock.now += 30
        r3.battery = level
        r3.state("charging")
        manager.check_timeouts()
        assert (tour.robot == "R3") is (level > enough)


async def test_a_robot_no_charge_can_fit_to_the_queued_tour_is_not_sent_to_charge_for_it(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    """A queued tour that even a full battery would not last is no reason to charge: a robot
    idle at a station would else charge to full, end its charge, and be given another at
    every dispatch."""
    for name in ("R1", "R2"):
        manager.robots[name].node = "hall"
    probe = Task("p", "tour", {"tour": "ground"}, 5, "", 0)
    drain = 1.0 / manager.estimator.task_s(probe, "charge_a")  # the whole battery and more
    r3 = RobotStub(bus, "R3", "charge_a", battery=0.9 + drain * 10)
    r3.state("idle")
    clock.now += 10
    r3.battery = 0.9
    r3.state("idle")
    tour = manager.request("tour", {"tour": "ground"})
    assert tour.state is TaskState.QUEUED
    assert manager.current_of(manager.robots["R3"]) is None
