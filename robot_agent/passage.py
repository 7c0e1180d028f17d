"""Passage through the building: the restricted areas, doors and elevators on the robot's path.

The navigator (robot_agent/navigation.py) follows the path node by node and asks this class
before each one whether it may go on; what the robot knows of the building and what it asked
of it lives here, apart from route following. For each path
- each restricted area is asked of the Traffic Manager before entering it and released after
  leaving it; a grant is never used while the link is down (the server may release it, offline
  grace) and is asked for again after a reconnect;
- every door within ``lookahead_m`` ahead is asked to open, on every pass, held until the robot
  has passed it (release_door), and the robot never drives onto a door node the building does
  not report open (door_opened / door_closed follow the door's sensor); a door that fails to
  open stops it in front (state door_blocked, robot_fault kind door_blocked) and it asks again
  every ``door_retry_s`` until ``wait_timeout_s``;
- elevators ahead are called once the robot holds the lift's area (its turn); the robot
  waits for elevator_in_position on its floor, rides, gets out; it never drives into a cabin
  that is not at its floor with the door open, and gets out only while the cabin stands open
  at its floor (called there to keep the door open).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Callable

from guidebot.messages import Message
from guidebot.payloads.building import CallElevator, OpenDoor, ReleaseDoor
from guidebot.payloads.robot import RobotFault
from guidebot.payloads.traffic import ReleaseArea, RequestArea
from guidebot.site.steps import PathStep
from robot_agent.motion import MotionControl, NavigationError, NavState

__all__ = ["CABIN_HOLD_CALL_S", "WAIT_LOG_S", "Passage"]

log = logging.getLogger(__name__)


CABIN_HOLD_CALL_S = 3.0
"""Robot seconds between two calls that keep a cabin's door open while the robot drives in."""
WAIT_LOG_S = 60.0
"""Robot seconds between two "still waiting for ..." warnings."""

Called = set[tuple[str, str]]
"""(elevator, floor) calls made on this pass of a path."""


class Passage:
    """Areas, doors and elevators for one robot's navigator (used by composition).

    It stops the base and shows what it waits for in the navigator's state; ``check`` raises
    when a wait must end (a base fault, a yield request); ``news`` is set by whoever learns
    something a wait watches (the building's broadcasts here, faults and yields in the
    navigator)."""

    def __init__(
        self,
        motion: MotionControl,
        *,
        check: Callable[[], None],
        news: asyncio.Event,
        lookahead_m: float = 8.0,
        wait_timeout_s: float = 600.0,
        door_retry_s: float = 5.0,
    ) -> None:
        self.motion = motion
        self.ep = motion.ep
        self.clock = motion.clock
        self.robot = motion.robot
        self.lookahead_m = lookahead_m
        self.wait_timeout_s = wait_timeout_s
        self.door_retry_s = door_retry_s
        self._check = check
        self._news = news
        self.held_areas: set[str] = set()
        """Areas acquired for the path ahead (entered or about to be)."""
        self.inside: str | None = None
        """The restricted area of the node the robot stands on (None: outside every area)."""
        self.edge_areas: set[str] = set()
        """Areas of the nodes the robot drove toward since it last reached a node: stopped on
        the edge (a fault, a cancel), it may be inside them, as the Traffic Manager counts
        (backend/traffic/whereabouts.py), so they are kept until it reaches a node."""
        self._doors_open: set[str] = set()
        self._held_doors: set[str] = set()
        # id of our last open_door request -> door; the reason when the building refused it.
        self._door_requests: dict[str, str] = {}
        self._door_failed: dict[str, str] = {}
        self._door_shut: set[str] = set()
        """Doors whose open_door the building answered ``door_closed`` (staff closed the door
        while it waited): asked again after ``door_retry_s``."""
        self._elevators: dict[str, str] = {}
        self.arrivals: dict[str, tuple[int, str]] = {}
        """Elevator -> (how many times the building's broadcasts said its cabin came to stand
        at a floor with its door open, that floor the last time): a riding robot waits for the
        next one. Replies to calls are not counted: one to a call that kept the door open
        while the robot drove in may come after the cabin left."""
        self.riding: tuple[str, str, str] | None = None
        """(elevator, from floor, to floor) while the robot rides a cabin."""
        self._granted: set[str] = set()
        self._gone: set[str] = set()
        """Areas of this path the server says a publish removed: not asked for again."""
        self._link_down = False
        """The link is down: the server may release a granted area it never saw us enter
        (docs/server.md, offline grace), so no granted area is entered until it is back."""
        self._waiting_area: str | None = None
        self._wait_retry: Callable[[], None] | None = None

    def handlers(self) -> dict[str, Callable[[Message], None]]:
        """The building's and the Traffic Manager's messages this class follows."""
        return {
            "door_opened": self._on_door,
            "door_closed": self._on_door,
            "command_failed": self._on_command_failed,
            "elevator_in_position": self._on_elevator,
            "area_granted": self._on_area_granted,
        }

    # -- message handlers (inline, never block) ----------------------------------------------

    def _on_door(self, message: Message) -> None:
        door = str(message.payload.get("door"))
        if message.type == "door_opened":
            self._doors_open.add(door)
        else:
            self._doors_open.discard(door)
            if self._door_requests.pop(message.correlation_id or "", None) is not None:
                self._door_shut.add(door)  # the answer to our open_door: staff closed it
        self._news.set()

    def _on_command_failed(self, message: Message) -> None:
        door = self._door_requests.pop(message.correlation_id or "", None)
        if door is not None:
            self._door_failed[door] = str(message.payload.get("reason") or "refused")
            self._news.set()

    def _on_elevator(self, message: Message) -> None:
        p = message.payload
        elevator, floor = str(p.get("elevator")), str(p.get("floor"))
        if p.get("door_open", True):
            self._elevators[elevator] = floor
            if message.destination is None:
                self.arrivals[elevator] = (self.arrived(elevator) + 1, floor)
        elif self._elevators.get(elevator) == floor:
            del self._elevators[elevator]
        self._news.set()

    def _on_area_granted(self, message: Message) -> None:
        p = message.payload
        if p.get("robot") in (None, self.robot):
            area = str(p.get("area"))
            if p.get("removed"):  # a publish took the area off the site: nothing to hold
                log.info("%s: %s", self.robot, p.get("reason") or f"area {area} removed")
                self._gone.add(area)
            else:
                self._granted.add(area)
            self._news.set()

    # -- the link ---------------------------------------------------------------------------------

    def link_lost(self) -> None:
        """Without the link the building's broadcasts are missed: doors and cabins become
        unknown, and unknown is closed (the robot stops before them until told again). A
        robot once drove into a cabin that had left while its link was down (the soak)."""
        self._link_down = True
        self._forget_building()

    def _forget_building(self) -> None:
        self._doors_open.clear()
        self._elevators.clear()
        self._news.set()

    def resync(self) -> None:
        """The link is back (maybe to a restarted server that never saw the requests): ask
        again for the area the robot stands waiting for, the doors it holds and the elevator
        it waits for; the answers say how things stand. Repeated requests are harmless.

        Areas granted but not entered are forgotten, even those the robot was about to enter
        (waiting at the edge for a door or a cabin): while we were away the server may have
        released them (offline grace), or restarted without them, and granted them to another
        robot. Each is asked for again at its edge (the soak saw two robots drive into one
        cabin when this kept the grant of a robot waiting for the lift)."""
        self._link_down = False
        self._forget_building()  # whatever was missed meanwhile is asked again below
        if stale := (self._granted | self.held_areas) - {self.inside} - self.edge_areas:
            log.info("%s: granted areas %s not entered: asked again", self.robot, sorted(stale))
            self._granted -= stale
            self.held_areas -= stale
        if self._waiting_area is not None:
            log.info("%s: still waiting for area %s: asked again", self.robot, self._waiting_area)
            self.ep.publish(RequestArea(robot=self.robot, area=self._waiting_area))
        for door in sorted(self._held_doors):
            self._open_door(door)
        if self._wait_retry is not None and self._waiting_area is None:
            self._wait_retry()  # (the area waited for was asked again above)

    # -- restricted areas -------------------------------------------------------------------------

    def areas_held(self) -> list[str]:
        """Areas held or granted ahead (robot_state ``areas``: the server's resync)."""
        return sorted(self.held_areas | self._granted)

    def must_ask(self, area: str) -> bool:
        """Entering ``area`` needs a grant we hold now, with the link up (docs/robot.md,
        "Link down"); the area the robot already stands in, or one a publish removed from
        the site (this path was planned before), needs nothing more."""
        if area == self.inside or area in self._gone:
            return False
        return area not in self.held_areas or self._link_down

    def new_path(self) -> None:
        """A path starts: it was planned on the site as it is, so areas gone from an earlier
        one are asked for again if it names them (a later publish may have brought them back).
        A grant held for no path (it came after the last path ended: the answer to a request
        of a wait that path gave up) is given back: the server may release it at the robot's
        next robot_state between tasks and grant it to another robot, and a path that drove
        in on it shared the lift with that robot (the fault soak). It is asked for again at
        the area's edge."""
        self._gone.clear()
        self._give_back(self._granted - self.held_areas - self.edge_areas - {self.inside})

    async def acquire_area(self, area: str) -> None:
        """Hold ``area`` before entering it: granted ahead, or asked for and waited for."""
        if area in self._granted and not self._link_down:
            # Granted ahead as part of a chain of back-to-back areas.
            self.held_areas.add(area)
            return
        self.motion.state = NavState.WAITING_AREA
        self.motion.halt(force=False)
        if area not in self._granted:
            self.ep.publish(RequestArea(robot=self.robot, area=area))
        else:
            log.warning("%s: link down: area %s is not entered until it is back", self.robot, area)
        self._waiting_area = area

        def ask_again() -> None:  # keeps its place in line (backend/traffic/locks.py)
            if not self._link_down:
                self.ep.publish(RequestArea(robot=self.robot, area=area))

        try:
            # Patient: the server grants areas in order, breaks deadlocks and frees those of
            # lost robots, so only time without the link counts towards the time-out (issue
            # 36: tours failed "timed out waiting for area elevator" behind a long lift queue).
            await self._wait_until(
                lambda: (area in self._granted or area in self._gone) and not self._link_down,
                f"area {area}",
                retry=ask_again,
                patient=True,
            )
        finally:
            self._waiting_area = None
        self.motion.state = NavState.MOVING
        if area not in self._granted:
            log.info("%s: area %s is gone from the site: going on without it", self.robot, area)
            return
        log.info("%s: area %s granted", self.robot, area)
        self.held_areas.add(area)

    def release_left(self, here: PathStep, nxt: PathStep | None) -> None:
        """Areas neither of ``here`` nor of the next node are behind the robot: released."""
        keep = {here.area, nxt.area if nxt else None}
        for area in sorted(self.held_areas - keep):
            self.held_areas.discard(area)
            self._granted.discard(area)
            log.info("%s: left area %s, released", self.robot, area)
            self.ep.publish(ReleaseArea(robot=self.robot, area=area))

    def release_not_entered(self) -> None:
        """A path ended early (a fault, a cancel) leaves areas acquired but not entered: give
        them back. Kept, the next path would drive in on them, though the server may have
        released them with the task meanwhile (the soak saw a robot enter a lift granted to
        another). Grants never used are given back too (dropped silently, they stayed the
        robot's on the server). An area of the edge the robot stopped on is kept
        (``edge_areas``): it may be inside it, and released, another robot could be granted it
        while this one still stands in its way."""
        self._give_back((self.held_areas | self._granted) - {self.inside} - self.edge_areas)

    def _give_back(self, areas: set[str]) -> None:
        """Release ``areas``, held or only granted (dropped silently, a grant stayed the
        robot's on the server)."""
        for area in sorted(areas):
            self.held_areas.discard(area)
            self._granted.discard(area)
            log.info("%s: area %s not entered, released", self.robot, area)
            self.ep.publish(ReleaseArea(robot=self.robot, area=area))

    def give_up(self, area: str) -> None:
        """Yielding ``area`` (the Traffic Manager's deadlock rule): released if held or granted."""
        if area in self.held_areas or area in self._granted:
            self.held_areas.discard(area)
            self._granted.discard(area)
            self.ep.publish(ReleaseArea(robot=self.robot, area=area))

    # -- doors and elevators ahead ----------------------------------------------------------------

    def ask_ahead(
        self, steps: list[PathStep], i: int, doors_ahead: dict[int, str], called: Called
    ) -> None:
        """Open doors and call elevators within ``lookahead_m`` of path ahead."""
        distance = math.hypot(steps[i].x - self.motion.x, steps[i].y - self.motion.y)
        j = i
        while j < len(steps) and (distance <= self.lookahead_m or j == i):
            s = steps[j]
            if s.door is not None and j not in doors_ahead:
                # Every pass asks: the building holds the door for this robot until release.
                doors_ahead[j] = s.door
                self._open_door(s.door)
            nxt = steps[j + 1] if j + 1 < len(steps) else None
            if (
                s.elevator is not None
                and nxt is not None
                and nxt.elevator == s.elevator
                and nxt.floor != s.floor
                and (s.elevator, s.floor) not in called
                and not (s.area is not None and self.must_ask(s.area))
            ):
                # Only the robot whose turn it is calls the cabin: one called by robots
                # waiting for the lift's area came and went for nobody, and the robot whose
                # turn came had its call spent (the soak: 70-90 s waits for a 20 s ride).
                called.add((s.elevator, s.floor))
                if self._elevators.get(s.elevator) != s.floor:
                    self.ep.publish(CallElevator(elevator=s.elevator, floor=s.floor))
            if j + 1 < len(steps):
                distance += math.hypot(steps[j + 1].x - s.x, steps[j + 1].y - s.y)
            j += 1

    def release_passed(self, i: int, doors_ahead: dict[int, str]) -> None:
        """Doors whose node is behind the robot are let go (unless asked again further on)."""
        for index in [k for k in doors_ahead if k < i]:
            door = doors_ahead.pop(index)
            if door not in doors_ahead.values() and door in self._held_doors:
                self._held_doors.discard(door)
                log.info("%s: passed door %s, released", self.robot, door)
                self.ep.publish(ReleaseDoor(door=door))

    def release_doors(self) -> None:
        """Let go of every door held (the path ended or the goal was cancelled)."""
        for door in sorted(self._held_doors):
            self.ep.publish(ReleaseDoor(door=door))
        self._held_doors.clear()
        self._door_requests.clear()
        self._door_shut.clear()

    def _open_door(self, door: str) -> None:
        """Ask the building to open (and hold) ``door`` for this robot."""
        self._held_doors.add(door)
        self._door_failed.pop(door, None)
        self._door_shut.discard(door)
        for request, known in list(self._door_requests.items()):
            if known == door:
                del self._door_requests[request]
        message = self.ep.publish(OpenDoor(door=door))
        self._door_requests[message.id] = door

    def passable(
        self, step: PathStep, cabin: bool, *, leaving: PathStep | None = None
    ) -> Callable[[], bool]:
        """While driving onto ``step``: is its area still ours, its door open, its cabin here
        (``cabin``: driving in) or the cabin the robot gets out of (``leaving``: its stop)
        still open at its floor? The cabin is called again now and then, as a person keeps the
        button pressed; getting out, at once: its door has stood open since it arrived."""
        door, area = step.door, step.area
        held = (
            (step.elevator, step.floor)
            if cabin
            else (leaving.elevator, leaving.floor)
            if leaving is not None
            else None
        )
        next_hold = self.clock.now() + (CABIN_HOLD_CALL_S if cabin else 0.0)

        def clear() -> bool:
            nonlocal next_hold
            if area is not None and self.must_ask(area):
                return False
            if door is not None and door not in self._doors_open:
                return False
            if held is None:
                return True
            elevator, floor = held
            assert elevator is not None  # a cabin's step names its elevator
            if self._elevators.get(elevator) != floor:
                return False
            if self.clock.now() >= next_hold:
                # Driving in or out: call again, as a person keeps the button pressed, so the
                # cabin door does not close on the robot (the soak saw it close under one).
                next_hold = self.clock.now() + CABIN_HOLD_CALL_S
                self.ep.publish(CallElevator(elevator=elevator, floor=floor))
            return True

        return clear

    def stopped_before(self, step: PathStep, called: Called) -> None:
        """The robot stopped before ``step`` (not passable): its cabin is called again on the
        next try, its door asked again if it closed under our hold."""
        called.discard((step.elevator or "", step.floor))
        if step.door is not None and step.door not in self._doors_open:
            self._open_door(step.door)  # closed under our hold: ask again

    # -- waits ------------------------------------------------------------------------------------

    async def wait_door(self, door: str) -> None:
        """Stand still until the building reports ``door`` open; a refusal is an alert."""
        if door in self._doors_open:
            return
        if door not in self._held_doors:
            self._open_door(door)
        self.motion.state = NavState.WAITING_DOOR
        self.motion.halt()
        deadline = self.clock.now() + self.wait_timeout_s
        retry_at: float | None = None
        alerted = False
        while door not in self._doors_open:
            self._news.clear()
            self._check()
            now = self.clock.now()
            reason = self._door_failed.get(door)
            if reason is not None and retry_at is None:
                self.motion.state = NavState.DOOR_BLOCKED
                self.motion.halt()
                log.warning("%s: door %s did not open: %s", self.robot, door, reason)
                if not alerted:
                    alerted = True
                    detail = f"door {door} did not open: {reason}"
                    self.ep.publish(
                        RobotFault(robot=self.robot, kind="door_blocked", detail=detail)
                    )
                retry_at = now + self.door_retry_s
            if door in self._door_shut and retry_at is None:
                log.info(
                    "%s: staff closed door %s while it waited: asking again in %g s",
                    self.robot,
                    door,
                    self.door_retry_s,
                )
                retry_at = now + self.door_retry_s
            if now >= deadline:
                raise NavigationError(
                    f"door {door} did not open within {self.wait_timeout_s:g} s"
                    + (f": {reason}" if reason else "")
                )
            if retry_at is not None and now >= retry_at:
                retry_at = None
                self._open_door(door)
            with contextlib.suppress(TimeoutError):  # not wait_for: see _wait_until
                async with asyncio.timeout(self.clock.wall(1.0) + 0.05):
                    await self._news.wait()
        log.info("%s: door %s open", self.robot, door)
        self.motion.state = NavState.MOVING

    async def wait_elevator(self, elevator: str, floor: str, called: Called) -> None:
        """Stand still until ``elevator``'s cabin is at ``floor`` with its door open; called
        now unless here (a call made ahead may have been served and the cabin gone since:
        a second call costs nothing, a spent one a retry period)."""
        if self._elevators.get(elevator) != floor:
            self.ep.publish(CallElevator(elevator=elevator, floor=floor))
        called.add((elevator, floor))
        if self._elevators.get(elevator) == floor:
            return
        self.motion.state = NavState.WAITING_ELEVATOR
        self.motion.halt(force=False)

        def resend() -> None:
            self.ep.publish(CallElevator(elevator=elevator, floor=floor))

        await self._wait_until(
            lambda: self._elevators.get(elevator) == floor, f"elevator {elevator}", retry=resend
        )

    async def ride(self, cabin: PathStep, exit_: PathStep) -> None:
        """In the cabin at ``cabin.floor``: send it to ``exit_.floor`` and wait until it is
        there with its door open (the navigator then re-anchors the pose and gets out)."""
        assert cabin.elevator is not None
        self.motion.state = NavState.RIDING
        self.motion.halt()
        self._elevators.pop(cabin.elevator, None)
        log.info("%s: riding elevator %s to floor %s", self.robot, cabin.elevator, exit_.floor)
        self.ep.publish(CallElevator(elevator=cabin.elevator, floor=exit_.floor))
        elevator = cabin.elevator

        def resend() -> None:
            self.ep.publish(CallElevator(elevator=elevator, floor=exit_.floor))

        self.riding = (elevator, cabin.floor, exit_.floor)
        try:
            await self._wait_until(
                lambda: self._elevators.get(elevator) == exit_.floor,
                f"elevator {elevator} to {exit_.floor}",
                retry=resend,
            )
        finally:
            self.riding = None

    def open_at(self, elevator: str) -> str | None:
        """The floor where the robot last heard ``elevator``'s door open (None while riding,
        until the cabin is somewhere)."""
        return self._elevators.get(elevator)

    def arrived(self, elevator: str) -> int:
        """How many arrivals of ``elevator``'s cabin the building has reported so far."""
        return self.arrivals.get(elevator, (0, ""))[0]

    async def wait_landing(self, elevator: str, after: int) -> str:
        """In ``elevator``'s cabin, calling nothing: the floor of its next arrival (door open)
        after the ``after``-th (a fire alarm's evacuation gets out there). Not the floor where
        the robot last knew the door open: the building's sensors lag, and the cabin may
        already be on its way."""
        self.motion.state = NavState.RIDING
        self.motion.halt()
        await self._wait_until(
            lambda: self.arrived(elevator) > after, f"elevator {elevator} to stop"
        )
        return self.arrivals[elevator][1]

    async def _wait_until(
        self,
        ready: Callable[[], bool],
        what: str,
        *,
        retry: Callable[[], None] | None = None,
        patient: bool = False,
    ) -> None:
        """Wait until ``ready``; NavigationError after ``wait_timeout_s`` (``patient``: of
        time with the link down only)."""
        started = self.clock.now()
        deadline = started + self.wait_timeout_s
        # Re-ask no sooner than the building's own time-out (a few wall seconds).
        retry_every = max(10.0, 7.0 * self.clock.time_scale)
        next_retry = started + retry_every
        # What the robot stands waiting for is in its log: at once, then every WAIT_LOG_S.
        next_log: float | None = None
        self._wait_retry = retry  # a reconnect asks again at once (resync)
        try:
            while True:
                self._news.clear()
                self._check()
                if ready():
                    if next_log is not None:
                        waited = self.clock.now() - started
                        log.info("%s: %s came after %.0f s", self.robot, what, waited)
                    return
                now = self.clock.now()
                if patient and not self._link_down:
                    deadline = now + self.wait_timeout_s
                if next_log is None or now >= next_log:
                    if next_log is None:
                        log.info("%s: waiting for %s", self.robot, what)
                    else:
                        log.warning(
                            "%s: still waiting for %s after %.0f s (gives up after %.0f s%s)",
                            *(self.robot, what, now - started, self.wait_timeout_s),
                            " without the link" if patient else "",
                        )
                    next_log = now + WAIT_LOG_S
                if now >= deadline:
                    raise NavigationError(f"timed out waiting for {what}")
                if retry is not None and now >= next_retry:
                    retry()
                    next_retry = now + retry_every
                # asyncio.timeout, not wait_for: on Python 3.11 wait_for swallows a
                # cancellation that coincides with the wake-up, and the cancelled goal would
                # drive on.
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(self.clock.wall(1.0) + 0.05):
                        await self._news.wait()
        finally:
            self._wait_retry = None
