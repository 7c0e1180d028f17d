"""A robot reserved ahead for each booked occurrence (docs/server.md, "Bookings").

How far ahead (``lead_s``): long enough for any robot to end the longest visitor task it may
have just started and drive across the site to the meeting point, plus ``MARGIN_S``; all in
real seconds (the ETA estimator's learned factors, backend/tasks/eta.py), so a fleet at a
higher time scale, or with short tours, reserves later and keeps its robots for walk-ups.

Which robot: among those in service, online, sound, not due to charge and charged enough for
the way and the tour, the one that can be at the meeting point ``MARGIN_S`` before the time
(its current task's remaining seconds, then its way from where that task ends), an idle one
first, then the soonest there. Every pass looks again: the robot's leaving time follows where
it is; one that would be late is swapped for one in time; one no longer fit is given up and
another chosen. At its leaving time it is sent to the meeting point (a ``go_to`` task), then
kept there; the booked tour is pinned to it at its time.

The Task Manager asks ``keeps(robot, task)`` before giving a robot a task (a reserved robot
takes no walk-up that would make it late, counting its way from where the walk-up ends) and
``parks(robot)`` before sending an idle robot to a station (the reserved robot waits at its
meeting point); the ETA estimator asks ``back_after`` so a walk-up's wait counts the
reservation (backend/tasks/manager.py, backend/tasks/eta.py). The scheduler asks ``arrival``
to tell staff ahead when the reserved robot cannot be there in time (backend/bookings/
schedule.py).

Kept across a restart: a reservation whose robot was already sent is found again from its
``go_to`` task (requester ``booking:<id>@<time>:meet``), which the Task Manager keeps; one not
yet sent is simply chosen again by the next pass.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from backend.tasks.battery_forecast import (
    CHARGED,
    charge_rate,
    charged_level,
    lasts_from,
    latest_charge_start,
)
from backend.tasks.charging import finish_floor
from backend.tasks.choice import nearest
from backend.tasks.model import Task, TaskError, TaskState
from backend.tasks.robots import RobotInfo

__all__ = ["MARGIN_S", "MEET_SUFFIX", "Reservation", "Reservations"]

log = logging.getLogger(__name__)

MARGIN_S = 60.0
"""A reserved robot is sent to arrive this long before the booked time."""
UNKNOWN_TRAVEL_S = 300.0
"""The way to the meeting point when no path is known (a robot not placed yet)."""
RELEASE_FACTOR = 1.5
"""A reservation not yet sent whose time is further off than this many leads is given back
(the lead shrank as the fleet's real speed was learned): its robot serves walk-ups freely."""
MEET_SUFFIX = ":meet"
"""The requester of the ``go_to`` to the meeting point: the occurrence's, plus this."""
CHARGE_SLACK_S = 60.0
"""Charge ahead: a robot is reserved to charge once it must start within this many seconds
(of the end of its current task) to be charged enough when it leaves."""
CHARGE_MARGIN = 0.05
"""Charge ahead: the battery it is to have when it leaves, above what the way and the tour
take at its learned drain (an estimate that wobbles, a way to the station)."""


@dataclass
class Reservation:
    booking: str
    at: float
    """The booked time (Unix seconds)."""
    robot: str
    node: str
    """The meeting point's node."""
    leave_at: float
    """When it must set off (Unix seconds), from where it is (or where its task ends)."""
    ends_at: float
    """When the booked tour is expected to end."""
    requester: str
    """The occurrence's requester (``booking:<id>@<unix time>``): its tasks are not walk-ups."""
    sent: str | None = None
    """The go_to task that takes it to the meeting point, once given."""
    charge: bool = False
    """It lasts the booked tour only if it charges until it leaves: it takes no walk-up
    meanwhile (the Task Manager's idle robots go to a station), and is not given back."""

    @property
    def duration_s(self) -> float:
        return self.ends_at - self.at

    def view(self) -> dict[str, Any]:
        return {
            "robot": self.robot,
            "leave_at": self.leave_at,
            "sent": self.sent,
            "charge": self.charge,
        }


class Reservations:
    """The reservations of the coming occurrences, kept in memory (see the module's text for
    what survives a restart)."""

    def __init__(
        self, tasks: Any, *, margin_s: float = MARGIN_S, clock: Callable[[], float] = time.time
    ) -> None:
        self.tasks = tasks
        """The Task Manager (robots, tasks, graph, site, estimator, request, cancel)."""
        self.margin_s = margin_s
        self.clock = clock
        self.by_robot: dict[str, Reservation] = {}
        self.by_key: dict[tuple[str, float], Reservation] = {}
        self._meets: dict[str, Task] | None = None
        """The go_to tasks to meeting points found at the first pass (an earlier life's)."""
        self._farthest: dict[str, tuple[Any, float]] = {}
        """Meeting point's node -> (site, metres from the farthest point of interest)."""
        self._longest: tuple[Any, float, float, float] | None = None
        """(site, move factor, talk factor, the longest tour's real seconds)."""
        self._promised: set[str] = set()
        """This pass: robots a later occurrence counts on (``charge_ahead``)."""

    # -- hooks of the Task Manager and the ETA estimator ------------------------------------

    def keeps(self, robot: RobotInfo, task: Task) -> bool:
        """The robot is reserved and ``task`` (not the booking's) would make it late: the
        task, then the way from where it ends to the meeting point."""
        r = self.by_robot.get(robot.name)
        if r is None or task.requester.startswith(r.requester):
            return False
        now = self.clock()
        if r.charge or now >= r.leave_at:
            return True
        took = self._task_s(task, robot.node)
        back = self.travel_s(robot, self._end_node(task) or robot.node, r.node)
        if now + took + back > r.at - self.margin_s:
            return True
        drain = robot.drain_per_s
        if drain is None or not math.isfinite(took):
            return False
        # ... or would leave its battery short of the booked tour.
        return not lasts_from(robot, robot.battery - drain * took, r.at - now - took, r.duration_s)

    def parks(self, robot: RobotInfo) -> bool:
        """Sent to its meeting point: it waits there, not at a station."""
        r = self.by_robot.get(robot.name)
        return r is not None and r.sent is not None

    def back_after(self, name: str, free_in_s: float, task: Task) -> float | None:
        """For a walk-up's wait: None if robot ``name`` may take ``task`` when it is free in
        ``free_in_s`` seconds, else in how many seconds it is free after its booking."""
        r = self.by_robot.get(name)
        if r is None or task.requester.startswith(r.requester):
            return None
        now = self.clock()
        if now + free_in_s + self._task_s(task, None) <= r.leave_at:
            return None
        return max(free_in_s, r.ends_at - now)

    # -- planning ----------------------------------------------------------------------------

    def lead_s(self, node: str) -> float:
        """How long before its time an occurrence meeting at ``node`` gets its robot: the
        margin, the longest tour a robot may have just started, and the longest way to
        ``node`` from a point of interest (where tours end) or a robot (real seconds)."""
        far = self.tasks.graph.distances_to(node)
        site = self.tasks.site
        found = self._farthest.get(node)
        if found is None or found[0] is not site:
            known = [far.get(p.node) for p in site.pois]
            found = (site, max((m for m in known if m is not None), default=0.0))
            self._farthest[node] = found
        robots = self.tasks.robots.values()
        here = [far.get(r.node) for r in robots if r.node]
        metres = max([found[1], *(m for m in here if m is not None)])
        speed = min((r.config.max_speed_mps for r in robots), default=0.5)
        way = metres / max(speed, 0.05) * self.tasks.estimator.move.value
        return self.margin_s + self._longest_s() + way

    def reserve(
        self, key: tuple[str, float], requester: str, node: str, duration_s: float
    ) -> Reservation | None:
        """The occurrence's robot, looked at again at every pass: one not sent yet that cannot
        be there by the time, or one whose battery will not last until the tour ends (sent or
        not: see ``lasts``), is swapped for one that can, if any, even one reserved for a
        later occurrence (which chooses again: the scheduler goes in time order). None when
        no robot fits now."""
        found = self.by_key.get(key)
        if found is None and (adopted := self._adopt(key, requester, node, duration_s)):
            return adopted
        now = self.clock()
        if found is not None:
            robot = self.tasks.robots.get(found.robot)
            if robot is not None and self._fits(robot) and self._enough(robot, found):
                if found.sent is not None or now + self.ready_in(robot, node) <= key[1]:
                    return found
        choice = self._choose(key, node, duration_s)
        if choice is None or (found is not None and choice[1]):
            return found  # nothing better: staff are told (schedule.py)
        robot, _, charge = choice
        if found is not None:
            log.info(
                "booking %s: %s late or short of battery, %s instead",
                key[0],
                found.robot,
                robot.name,
            )
            self._unsend(found)
            self.release(key)
        taken = self.by_robot.get(robot.name)
        if taken is not None:
            log.info("booking %s: %s taken for an earlier one", taken.booking, robot.name)
            self.release((taken.booking, taken.at))
        return self._take(key, requester, node, duration_s, robot, charge=charge)

    def charge_ahead(
        self, key: tuple[str, float], requester: str, node: str, duration_s: float
    ) -> Reservation | None:
        """Before the lead (the scheduler goes in time order): when no robot free of
        reservations will last until the booked tour ends by working on (``lasts``), the one
        that can work longest before it must charge to be charged enough when it leaves
        (battery_forecast.py ``latest_charge_start``) is reserved to charge once that is
        ``CHARGE_SLACK_S`` away. A fleet that drains alike reaches ``battery_low`` together
        and charges for minutes: a booking then had no robot. A robot that will have charged
        in full (due to charge now, or once it reaches ``battery_low``) before it must leave
        serves too. Robots counted on (lasting, charging in full in time, or charging ahead
        later) are not counted again by a later occurrence in the same pass."""
        found = self.by_key.get(key)
        if found is not None:
            return found
        at = key[1]
        best: tuple[float, RobotInfo] | None = None
        for robot in self.tasks.robots.values():
            if robot.name in self.by_robot or robot.name in self._promised:
                continue
            if self._back_full(robot, node, at, duration_s):
                self._promised.add(robot.name)
                return None  # its own charge brings it back in time
            if not self._fits(robot):
                continue
            if self.lasts(robot, at, duration_s):
                self._promised.add(robot.name)
                return None  # it serves this one, working on until then
            level, start, leave = self._charge_plan(robot, node, at)
            need = self._need(robot, at - leave, duration_s)
            latest = latest_charge_start(robot, level, start, leave, need, self._fleet())
            if latest is not None and (best is None or latest - start > best[0]):
                best = (latest - start, robot)
        if best is None:
            return None  # no charge gets one there: staff are told at the lead
        slack, robot = best
        self._promised.add(robot.name)
        if slack > CHARGE_SLACK_S:
            return None  # it works on a while yet
        log.info("booking %s: %s charges ahead for it", key[0], robot.name)
        return self._take(key, requester, node, duration_s, robot, charge=True)

    def refresh(self, now: float) -> None:
        """Every pass, before ``reserve``: a reserved robot no longer fit is given up (the
        occurrence chooses again); the leaving time of one not yet sent follows where it is;
        one whose way to the meeting point ended short is sent again."""
        self._promised.clear()
        for r in list(self.by_key.values()):
            robot = self.tasks.robots.get(r.robot)
            if r.sent is not None:
                meet = self.tasks.tasks.get(r.sent)
                if meet is None or not meet.final or meet.state is TaskState.DONE:
                    continue
                r.sent = None  # failed or cancelled on the way: sent again
            if robot is None or not self._fits(robot):
                self.drop(r, f"{r.robot} is no longer fit")
                continue
            r.leave_at = self._leave_at(robot, r.node, r.at)
            if r.charge and self.lasts(robot, r.at, r.duration_s):
                r.charge = False  # charged enough: walk-ups that leave it so, and given back
                # when its time is far (``too_early``)

    def arrival(self, key: tuple[str, float]) -> tuple[str, float] | None:
        """(robot, when it can be at the meeting point) for a reserved occurrence, else None."""
        r = self.by_key.get(key)
        robot = self.tasks.robots.get(r.robot) if r is not None else None
        if r is None or robot is None:
            return None
        return r.robot, self.clock() + self.ready_in(robot, r.node)

    def send(self, now: float) -> None:
        """Reserved robots whose time to leave has come go to their meeting points."""
        for r in list(self.by_key.values()):
            if r.sent is not None or now < r.leave_at:
                continue
            robot = self.tasks.robots.get(r.robot)
            if robot is None or not self._fits(robot):
                self.drop(r, f"{r.robot} is no longer fit")
                continue
            if not self.idle(robot):
                continue  # still on a task given before the reservation: it goes after
            try:
                task = self.tasks.request(
                    "go_to",
                    {"node": r.node},
                    priority=50,
                    requester=r.requester + MEET_SUFFIX,
                    robot=r.robot,
                )
            except TaskError as exc:
                log.warning("booking %s: cannot send %s to meet: %s", r.booking, r.robot, exc)
                continue
            r.sent = task.id

    def pinned(self, key: tuple[str, float]) -> str | None:
        """At its time: the reserved robot the booked task goes to (None: any), its way to
        the meeting point ended (cancelled if it has not arrived: the tour goes on from
        there). The caller releases the reservation once the booked task is made: until
        then the robot, idle, is kept from the walk-ups waiting (the soak saw one take it
        between the two, and the booked tour wait for its end)."""
        r = self.by_key.get(key)
        if r is None:
            return None
        if r.sent is not None:
            meet = self.tasks.tasks.get(r.sent)
            if meet is not None and not meet.final:
                try:
                    self.tasks.cancel(meet.id, reason="the booked tour starts", by="bookings")
                except TaskError:
                    pass
        robot = self.tasks.robots.get(r.robot)
        if robot is None or not self._fits(robot) or not self.idle(robot):
            return None  # lost, charging or still busy: the first robot free takes it
        return r.robot

    def release(self, key: tuple[str, float]) -> None:
        r = self.by_key.pop(key, None)
        if r is not None and self.by_robot.get(r.robot) is r:
            del self.by_robot[r.robot]

    def drop(self, r: Reservation, why: str) -> None:
        """Give a reservation up (its robot went out of service): the next pass chooses again."""
        log.info("booking %s: reservation of %s dropped: %s", r.booking, r.robot, why)
        self.release((r.booking, r.at))

    def forget_except(self, keys: set[tuple[str, float]]) -> None:
        """Drop reservations of occurrences no longer coming (cancelled, moved) or, not yet
        sent, further off than ``RELEASE_FACTOR`` leads."""
        for key in [k for k in self.by_key if k not in keys]:
            self.release(key)

    def too_early(self, key: tuple[str, float], node: str, now: float) -> bool:
        """Not reserved yet: its time is beyond the lead. Reserved: beyond RELEASE_FACTOR
        leads and not sent (kept, a lead that jitters would take and give back)."""
        lead = self.lead_s(node)
        r = self.by_key.get(key)
        if r is None:
            return key[1] - now > lead
        return r.sent is None and not r.charge and key[1] - now > lead * RELEASE_FACTOR

    # -- estimates -----------------------------------------------------------------------------

    def ready_in(self, robot: RobotInfo, node: str) -> float:
        """Real seconds until ``robot`` can be at ``node``: what its current task still takes,
        then its way from where that task ends (inf: held up, nobody can say)."""
        if robot.held_up:
            return math.inf
        current = self.tasks.tasks.get(robot.current) if robot.current else None
        if current is None or current.internal or current.final:
            return self.travel_s(robot, robot.node, node)
        if current.requester.endswith(MEET_SUFFIX) and current.params.get("node") == node:
            return self.travel_s(robot, robot.node, node)  # on its way there
        left = self._busy_s(robot)
        return left + self.travel_s(robot, self._end_node(current) or robot.node, node)

    def travel_s(self, robot: RobotInfo, start: str | None, node: str) -> float:
        """Real seconds of the way from ``start`` to ``node`` at the robot's speed, the lift's
        queue included (nominal seconds times the learned factor of legs)."""
        if start == node:
            return 0.0
        metres = self.tasks.graph.distances_to(node).get(start) if start else None
        if metres is None or not math.isfinite(metres):
            return UNKNOWN_TRAVEL_S
        nominal = float(metres) / robot.config.max_speed_mps + self.tasks.lift_wait_s(start, node)
        return nominal * self.tasks.estimator.move.value

    # -- helpers -----------------------------------------------------------------------------

    def _choose(
        self, key: tuple[str, float], node: str, duration_s: float
    ) -> tuple[RobotInfo, bool, bool] | None:
        """The robot to reserve, whether it is late (there after the time minus the margin)
        and whether it must charge until it leaves to last: in time first, then one not
        reserved, then one that lasts working on, then idle, then the soonest there (of those
        that must charge: the one charged most above its need when it leaves, ``_surplus``). A robot
        reserved for a later occurrence, not sent yet, is a candidate only in time."""
        now, at = self.clock(), key[1]
        best: tuple[tuple[bool, bool, bool, bool, float], RobotInfo] | None = None
        for robot in self.tasks.robots.values():
            other = self.by_robot.get(robot.name)
            if other is not None and (other.at <= at or other.sent is not None):
                continue
            if not self._fits(robot):
                continue
            charge = not self.lasts(robot, at, duration_s)
            if charge and not self.charges_enough(robot, at, duration_s, node):
                continue
            ready = self.ready_in(robot, node)
            late = now + ready > at - self.margin_s
            if late and other is not None:
                continue
            # One that must charge: the one charged most above what it needs (a robot at a
            # station before one that has yet to get there), not the one nearest: a robot that
            # barely charges enough is short a pass later, and was swapped (the first wave of
            # the soak's charges saw reservations go from robot to robot).
            rank = -self._surplus(robot, at, duration_s, node) if charge else ready
            cost = (late, other is not None, charge, not self.idle(robot), rank)
            if best is None or cost < best[0]:
                best = (cost, robot)
        return (best[1], best[0][0], best[0][2]) if best is not None else None

    def _take(
        self,
        key: tuple[str, float],
        requester: str,
        node: str,
        duration_s: float,
        robot: RobotInfo,
        sent: str | None = None,
        *,
        charge: bool = False,
    ) -> Reservation:
        at = key[1]
        r = Reservation(
            booking=key[0],
            at=at,
            robot=robot.name,
            node=node,
            leave_at=self._leave_at(robot, node, at),
            ends_at=at + duration_s,
            requester=requester,
            sent=sent,
            charge=charge,
        )
        self.by_key[key] = self.by_robot[robot.name] = r
        log.info(
            "booking %s at %.0f: %s reserved, leaves at %.0f%s",
            key[0],
            at,
            robot.name,
            r.leave_at,
            ", charging until then" if charge else "",
        )
        self.tasks.dispatch()
        return r

    def _adopt(
        self, key: tuple[str, float], requester: str, node: str, duration_s: float
    ) -> Reservation | None:
        """A robot already on its way to this meeting point (the go_to of an earlier life,
        kept by the Task Manager) stays the reserved one; the tasks are looked through once,
        at the first pass of a life."""
        if self._meets is None:
            self._meets = {
                t.requester: t
                for t in self.tasks.tasks.values()
                if not t.final and t.requester.endswith(MEET_SUFFIX) and t.robot
            }
        task = self._meets.pop(requester + MEET_SUFFIX, None)
        robot = self.tasks.robots.get(task.robot) if task is not None and task.robot else None
        if task is None or task.final or robot is None or robot.name in self.by_robot:
            return None
        return self._take(key, requester, node, duration_s, robot, sent=task.id)

    def lasts(self, robot: RobotInfo, at: float, duration_s: float) -> bool:
        """Working on, at its learned drain, its battery stays above ``battery_low`` until the
        booked time (else it is sent to charge first) and lasts the tour (``can_finish``); an
        unknown drain: yes."""
        return lasts_from(robot, robot.battery, at - self.clock(), duration_s)

    def charges_enough(self, robot: RobotInfo, at: float, duration_s: float, node: str) -> bool:
        """Charged at the nearest station from the end of its current visitor task until it
        must leave it for ``node`` (its learned charge rate, battery_forecast.py), it lasts
        until the tour ends; not if it reaches ``battery_low`` first (it would charge in
        full, due to charge)."""
        if robot.drain_per_s is None:
            return True
        level, start, leave = self._charge_plan(robot, node, at)
        if level <= robot.config.battery_low or start > leave:
            return False
        charged = charged_level(robot, level, leave - start, self._fleet())
        return lasts_from(robot, charged, at - leave, duration_s)

    def _surplus(self, robot: RobotInfo, at: float, duration_s: float, node: str) -> float:
        """How far above what the way and the tour take (``_need`` without its margin) its
        level is when it leaves the station, charged as ``charges_enough`` plans it (-inf:
        it reaches ``battery_low`` first, or has no time to charge)."""
        level, start, leave = self._charge_plan(robot, node, at)
        if level <= robot.config.battery_low or start > leave:
            return -math.inf
        charged = charged_level(robot, level, leave - start, self._fleet())
        return charged - (self._need(robot, at - leave, duration_s) - CHARGE_MARGIN)

    def _charge_plan(self, robot: RobotInfo, node: str, at: float) -> tuple[float, float, float]:
        """If it charges for the occurrence at ``node``: (its level when it reaches the
        station, when that is, when it must leave the station); no station: never."""
        now = self.clock()
        busy = self._busy_s(robot)
        free = self._free_node(robot)
        stations = self.tasks.site.charging_stations
        station = next((st for st in stations if st.node == free), None) or nearest(
            free, stations, self.tasks.graph.distances_to
        )
        if station is None:
            return robot.battery, math.inf, now
        way = self.travel_s(robot, free, station.node)
        level = robot.battery - (robot.drain_per_s or 0.0) * (busy + way)
        leave = at - self.margin_s - self.travel_s(robot, station.node, node)
        return level, now + busy + way, leave

    def _back_full(self, robot: RobotInfo, node: str, at: float, duration_s: float) -> bool:
        """Online and sound, due to charge or working on until ``battery_low``, it will have
        charged in full (``CHARGED``) at the nearest station before it must leave it, and
        then last, working on, until the tour at ``at`` ends (unknown drain: no)."""
        drain, rate = robot.drain_per_s, charge_rate(robot, self._fleet())
        if not robot.online or robot.fault or robot.out_of_service:
            return False
        if drain is None or rate is None or drain <= 0 or rate <= 0:
            return False
        level, start, leave = self._charge_plan(robot, node, at)
        if not robot.needs_charge:  # it works on until battery_low, then goes
            low = robot.config.battery_low
            start += max(0.0, (level - low) / drain)
            level = low
        full_at = start + max(0.0, CHARGED - level) / rate
        return full_at <= leave and lasts_from(robot, CHARGED, at - full_at, duration_s)

    def _enough(self, robot: RobotInfo, r: Reservation) -> bool:
        """The reserved robot lasts the booked tour, working on or charging until it leaves
        (then it charges: ``Reservation.charge``)."""
        if self.lasts(robot, r.at, r.duration_s):
            return True
        if self.charges_enough(robot, r.at, r.duration_s, r.node):
            r.charge = True
            return True
        return False

    def short_of_battery(self, key: tuple[str, float]) -> bool:
        """The reserved robot's battery will not last until the booked tour ends, even
        charging until it leaves."""
        r = self.by_key.get(key)
        robot = self.tasks.robots.get(r.robot) if r is not None else None
        return robot is not None and r is not None and not self._enough(robot, r)

    def _need(self, robot: RobotInfo, wait_s: float, duration_s: float) -> float:
        """The level to leave with: ``wait_s`` above ``battery_low``, then the tour above the
        finish floor, at its learned drain, plus ``CHARGE_MARGIN``."""
        drain = robot.drain_per_s or 0.0
        low = robot.config.battery_low + drain * max(0.0, wait_s)
        floor = finish_floor(robot) + drain * (max(0.0, wait_s) + duration_s)
        return max(low, floor) + CHARGE_MARGIN

    def _unsend(self, r: Reservation) -> None:
        """Call back a robot sent to a meeting point another robot now goes to."""
        meet = self.tasks.tasks.get(r.sent) if r.sent is not None else None
        if meet is not None and not meet.final:
            try:
                self.tasks.cancel(meet.id, reason="another robot takes the booking", by="bookings")
            except TaskError:
                pass

    def _fleet(self) -> Iterable[RobotInfo]:
        """The robots whose learned charge rate stands in for one that has not charged yet
        (battery_forecast.py ``charge_rate``)."""
        robots: Iterable[RobotInfo] = self.tasks.robots.values()
        return robots

    def _fits(self, robot: RobotInfo) -> bool:
        """In service, online, sound and not due to charge."""
        return (
            robot.online
            and not robot.out_of_service
            and not robot.fault
            and not robot.needs_charge
            and robot.battery > robot.config.battery_low
        )

    def idle(self, robot: RobotInfo) -> bool:
        """No visitor task (nothing, or the Task Manager's own errand: preemptible)."""
        current = self.tasks.tasks.get(robot.current) if robot.current else None
        return current is None or current.internal or current.final

    def _busy_s(self, robot: RobotInfo) -> float:
        """Real seconds its current visitor task still takes (0: none; inf: a target the
        site no longer has)."""
        current = self.tasks.tasks.get(robot.current) if robot.current else None
        if current is None or current.internal or current.final:
            return 0.0
        left = self.tasks.estimator.estimate(current).remaining_s
        if left is None or not math.isfinite(left):
            left = self._task_s(current, robot.node)
        return left

    def _leave_at(self, robot: RobotInfo, node: str, at: float) -> float:
        """When it must set off to be at ``node`` ``margin_s`` before ``at``."""
        return at - self.margin_s - self.travel_s(robot, self._free_node(robot), node)

    def _free_node(self, robot: RobotInfo) -> str | None:
        """Where the robot is once its current visitor task is over."""
        current = self.tasks.tasks.get(robot.current) if robot.current else None
        if current is None or current.internal or current.final:
            return robot.node
        return self._end_node(current) or robot.node

    def _end_node(self, task: Task) -> str | None:
        """Where ``task`` ends: a tour's last stop, a visit's point, else its target."""
        site = self.tasks.site
        if task.kind == "tour" and (tour := site.tour(str(task.params.get("tour")))) is not None:
            poi = site.poi(tour.points[-1]) if tour.points else None
            return poi.node if poi is not None else None
        try:
            return str(self.tasks.target_of(task.kind, task.params))
        except (TaskError, ValueError, KeyError):
            return None

    def _longest_s(self) -> float:
        """Real seconds of the site's longest tour (its way to the first stop included)."""
        est = self.tasks.estimator
        site = self.tasks.site
        found = self._longest
        if (
            found is not None
            and found[0] is site
            and found[1:3] == (est.move.value, est.talk.value)
        ):
            return found[3]
        tooks = [
            self._task_s(
                Task(
                    id="~lead", kind="tour", params={"tour": t.id}, priority=5, requester="", seq=0
                ),
                None,
            )
            for t in site.tours
        ]
        longest = max((t for t in tooks if math.isfinite(t)), default=UNKNOWN_TRAVEL_S)
        self._longest = (site, est.move.value, est.talk.value, longest)
        return longest

    def _task_s(self, task: Task, start: str | None) -> float:
        try:
            took = self.tasks.estimator.task_s(task, start)
        except Exception:  # a target the site no longer has: assume the worst
            return math.inf
        return took if took is not None and math.isfinite(took) else UNKNOWN_TRAVEL_S
