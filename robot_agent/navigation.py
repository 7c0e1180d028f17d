"""Navigation: follow the Traffic Manager's path with velocity commands and odometry back.

One goal at a time (a new navigate_to pre-empts the old one). For each path the navigator
- asks the Traffic Manager for each restricted area before entering it, releases it after
  leaving it;
- asks every door within ``lookahead_m`` ahead to open, on every pass, holds it until it has
  passed it (release_door) and never drives onto a door node the building does not report open
  (door_opened / door_closed follow the door's sensor); a door that fails to open stops it in
  front (state door_blocked, robot_fault kind door_blocked) and it asks again every
  ``door_retry_s`` until ``wait_timeout_s``;
- calls elevators ahead, waits for elevator_in_position on its floor, rides, gets out; it never
  drives into a cabin that is not at its floor with the door open;
- reports every node it reaches (node_reached: what the fleet's invariants are checked on);
- stops on bumper_hit, reports it as robot_fault, and goes on after ``bumper_pause_s``;
- stops for good on base_fault (a critical module lost) and fails the goal.

Pose: odometry arrives in the base's own frame; the navigator keeps the transform to the map
and re-anchors it on the path's first node and when it leaves an elevator (a new floor).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import Any

from guidebot.bus import BusEndpoint, RequestTimeout
from guidebot.messages import Message
from guidebot.payloads.building import OpenDoor, ReleaseDoor
from guidebot.payloads.petri import PeopleFaced
from guidebot.payloads.robot import NodeReached, RobotFault
from guidebot.payloads.traffic import GetPath, ReleaseArea, RequestArea
from guidebot.site.steps import PathStep
from robot_agent.clock import Clock
from robot_agent.motion import MotionControl, NavigationFailed, NavState, wrap_angle

__all__ = ["NavState", "NavigationFailed", "Navigator", "PathStep"]

log = logging.getLogger(__name__)


CABIN_HOLD_CALL_S = 3.0
"""Robot seconds between two calls that keep a cabin's door open while the robot drives in."""
WAIT_LOG_S = 60.0
"""Robot seconds between two "still waiting for ..." warnings."""


class YieldRequested(Exception):
    """The Traffic Manager asks this robot to back off from an area (deadlock resolution)."""

    def __init__(self, area: str, node: str) -> None:
        super().__init__(f"yield {area}, back off to {node}")
        self.area = area
        self.node = node


class Navigator(MotionControl):
    """The on-board navigation module (an endpoint on the on-board bus): route following
    (areas, doors, elevators, goals) over the motion control it inherits."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        clock: Clock,
        robot: str,
        *,
        start_node: str | None = None,
        max_speed: float = 0.7,
        max_turn: float = 1.5,
        tolerance_m: float = 0.15,
        lookahead_m: float = 8.0,
        bumper_pause_s: float = 3.0,
        wait_timeout_s: float = 600.0,
        path_timeout_s: float = 5.0,
        docking_s: float = 5.0,
        planner: Callable[[str, str], dict[str, Any]] | None = None,
        floor_of: Mapping[str, str] | None = None,
        position_of: Mapping[str, tuple[float, float]] | None = None,
        door_retry_s: float = 5.0,
    ) -> None:
        super().__init__(
            endpoint,
            clock,
            robot,
            max_speed=max_speed,
            max_turn=max_turn,
            tolerance_m=tolerance_m,
        )
        self.lookahead_m = lookahead_m
        self.bumper_pause_s = bumper_pause_s
        self.wait_timeout_s = wait_timeout_s
        self.path_timeout_s = path_timeout_s
        self.docking_s = docking_s
        self.door_retry_s = door_retry_s
        self.planner = planner
        """On-board map (the site graph): plans when the Traffic Manager cannot be reached."""
        self.plan_on_board = False
        """The planner holds the server's live site version (set when ``site_changed`` was
        applied): plan on board at once and only tell the Traffic Manager the path, saving the
        get_path round trip (the same graph and search give the same path)."""
        # Map pose and where the robot is in the graph.
        self.node: str | None = start_node
        self.floor: str | None = (floor_of or {}).get(start_node or "")
        self.localized = False
        self.goal: str | None = None
        self.held_areas: set[str] = set()
        """Areas acquired for the path ahead (entered or about to be)."""
        self.inside: str | None = None
        """The restricted area of the node the robot stands on (None: outside every area)."""
        self.bumps = 0
        self.yields = 0
        self._yield: YieldRequested | None = None
        if (start := (position_of or {}).get(start_node or "")) is not None:
            # Odometry starts at (0, 0): anchor it at the start node until the first path.
            self._tx, self._ty = start
            self.x, self.y = start
        self._doors_open: set[str] = set()
        self._held_doors: set[str] = set()
        # id of our last open_door request -> door; the reason when the building refused it.
        self._door_requests: dict[str, str] = {}
        self._door_failed: dict[str, str] = {}
        self._elevators: dict[str, str] = {}
        self._granted: set[str] = set()
        self._link_down = False
        """The link is down: the server may release a granted area it never saw us enter
        (docs/server.md, offline grace), so no granted area is entered until it is back."""
        self._waiting_area: str | None = None
        self._wait_retry: Callable[[], None] | None = None
        self._news = asyncio.Event()
        self._goal_task: asyncio.Task[None] | None = None

    # -- life cycle -------------------------------------------------------------------------

    async def on_start(self) -> None:
        self.subscribe_all(
            self.ep,
            {
                "navigate_to": self._on_navigate_to,
                "dock": self._on_dock,
                "face_people": self._on_face_people,
                "odometry": self._on_odometry,
                "bumper_hit": self._on_bumper,
                "base_fault": self._on_base_fault,
                "module_status": self._on_module_status,
                "door_opened": self._on_door,
                "door_closed": self._on_door,
                "command_failed": self._on_command_failed,
                "elevator_in_position": self._on_elevator,
                "area_granted": self._on_area_granted,
                "area_yield": self._on_area_yield,
            },
        )

    async def on_stop(self) -> None:
        await self.cancel()

    def cancel_goal(self) -> None:
        """Abandon the current goal now (its task was cancelled) and stop the base.

        Synchronous on purpose: a new goal published right after (the next task's first
        navigate_to) must not be hit by a cancellation that runs later.
        """
        task, self._goal_task = self._goal_task, None
        if task is not None and not task.done():
            task.cancel()
        self._send_velocity(0.0, 0.0, force=True)
        self._release_doors()
        if self.state is not NavState.FAULT:
            self.state = NavState.IDLE
        self.goal = None

    async def cancel(self) -> None:
        """cancel_goal, then wait until the goal's coroutine has unwound."""
        task = self._goal_task
        self.cancel_goal()
        if task is not None:
            with contextlib.suppress(asyncio.CancelledError):
                await task

    # -- message handlers (inline, never block) ----------------------------------------------

    def _on_navigate_to(self, message: Message) -> None:
        node = message.payload.get("node")
        if not isinstance(node, str) or not node:
            self.ep.publish(
                "navigation_failed",
                {"node": node, "reason": "navigate_to needs a node id"},
                correlation_id=message.id,
            )
            return
        self._start_goal(self._goal(node, message.id, reply="goal_reached"))

    def _on_dock(self, message: Message) -> None:
        """The battery_charge net is at the station's node: run the docking approach."""
        station = message.payload.get("station")
        node = message.payload.get("node") or self.node
        if not isinstance(node, str) or not node:
            self.ep.publish("navigation_failed", {"node": node, "reason": "dock: position unknown"})
            return
        self._start_goal(self._goal(node, message.id, reply="docked", station=station))

    def _on_face_people(self, message: Message) -> None:
        # Visitors follow the robot: they stand behind it. Turn around in place.
        self._start_goal(self._face_people(message.id))

    def _start_goal(self, coro: Any) -> None:
        previous = self._goal_task
        if previous is not None and not previous.done():
            previous.cancel()
        self._goal_task = asyncio.get_running_loop().create_task(coro, name="navigation-goal")

    def _on_bumper(self, message: Message) -> None:
        self.bumps += 1
        self._bumped_until = self.clock.now() + self.bumper_pause_s
        self._send_velocity(0.0, 0.0, force=True)
        detail = f"bumper ring {message.payload.get('ring')} index {message.payload.get('index')}"
        self.ep.publish(RobotFault(robot=self.robot, kind="bumper", detail=detail))
        self._news.set()

    def _on_base_fault(self, message: Message) -> None:
        self.fault = str(message.payload.get("reason") or "base fault")
        self.state = NavState.FAULT
        self._send_velocity(0.0, 0.0, force=True)
        self.ep.publish(RobotFault(robot=self.robot, kind="motor_lost", detail=self.fault))
        self._news.set()
        self._odom_event.set()

    def _on_module_status(self, message: Message) -> None:
        p = message.payload
        if self.fault is not None and p.get("critical") and p.get("state") == "online":
            log.info("%s: critical module %s back online, fault cleared", self.robot, p.get("name"))
            self.fault = None
            self.state = NavState.IDLE
            self._news.set()

    def _on_door(self, message: Message) -> None:
        door = str(message.payload.get("door"))
        if message.type == "door_opened":
            self._doors_open.add(door)
        else:
            self._doors_open.discard(door)
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
        elif self._elevators.get(elevator) == floor:
            del self._elevators[elevator]
        self._news.set()

    def _on_area_granted(self, message: Message) -> None:
        p = message.payload
        if p.get("robot") in (None, self.robot):
            self._granted.add(str(p.get("area")))
            self._news.set()

    def _on_area_yield(self, message: Message) -> None:
        p = message.payload
        if p.get("robot") not in (None, self.robot) or self._goal_task is None:
            return
        self._yield = YieldRequested(str(p.get("area")), str(p.get("go_to_node") or ""))
        self._news.set()
        self._odom_event.set()

    # -- goals --------------------------------------------------------------------------------

    async def _goal(self, node: str, request_id: str, *, reply: str, **extra: Any) -> None:
        self.goal = node
        try:
            for _attempt in range(4):
                try:
                    await self.go_to(node)
                    break
                except YieldRequested as request:
                    await self._back_off(request)
            else:
                raise NavigationFailed(f"asked to yield too often on the way to {node}")
        except NavigationFailed as failure:
            self._send_velocity(0.0, 0.0, force=True)
            self.ep.publish(
                "navigation_failed",
                {"node": node, "reason": failure.reason},
                correlation_id=request_id,
            )
            return
        finally:
            self.goal = None
        log.info("%s: reached %s", self.robot, node)
        if reply == "docked":
            await self.clock.sleep(self.docking_s)  # the final approach onto the contacts
        self.ep.publish(reply, {**extra, "node": node}, correlation_id=request_id)

    async def _back_off(self, request: YieldRequested) -> None:
        """Leave the area for its passing place, give it up, then the goal is tried again."""
        self.yields += 1
        self._yield = None
        self._send_velocity(0.0, 0.0, force=True)
        log.info("%s: yielding area %s, backing off to %s", self.robot, request.area, request.node)
        if request.node and request.node != self.node:
            await self.go_to(request.node)
        if request.area in self.held_areas or request.area in self._granted:
            self.held_areas.discard(request.area)
            self._granted.discard(request.area)
            self.ep.publish(ReleaseArea(robot=self.robot, area=request.area))

    async def _face_people(self, request_id: str) -> None:
        with contextlib.suppress(NavigationFailed):
            await self.turn_to(wrap_angle(self.theta + math.pi))
        self.ep.publish(PeopleFaced(), correlation_id=request_id)

    async def go_to(self, node: str) -> None:
        """Reach ``node``: plan with the Traffic Manager, then follow the path."""
        self._check_fault()
        if node == self.node:
            return
        log.info("%s: going from %s to %s", self.robot, self.node, node)
        self.state = NavState.PLANNING
        path = await self._get_path(node)
        await self.follow([PathStep.from_dict(s) for s in path.get("steps", [])])

    async def _get_path(self, node: str) -> dict[str, Any]:
        if self.plan_on_board and self.planner is not None and self.node is not None:
            try:
                path = self.planner(self.node, node)
            except Exception:  # the server answers why (unknown node, no path)
                pass
            else:
                # The Traffic Manager keeps each robot's path (head-on prevention): it is
                # told by the same request, whose answer nobody waits for.
                self.ep.publish(
                    "get_path", {"robot": self.robot, "from_node": self.node, "to_node": node}
                )
                return path
        attempts = 3 if self.planner is None else 1
        for attempt in range(attempts):
            try:
                reply = await self.ep.request(
                    GetPath(robot=self.robot, from_node=self.node, to_node=node),
                    timeout=self.path_timeout_s,
                )
            except RequestTimeout:
                log.warning("%s: no path to %s yet (attempt %d)", self.robot, node, attempt + 1)
                continue
            if reply.type != "path" or not reply.payload.get("steps"):
                reason = reply.payload.get("error") or reply.payload.get("reason") or reply.payload
                raise NavigationFailed(f"no path to {node}: {reason}")
            return reply.payload
        if self.planner is not None and self.node is not None:
            # The link is down: plan on the on-board map and go on alone (areas, doors and
            # elevators still wait for the server's answers).
            log.warning("%s: Traffic Manager silent, planning to %s on board", self.robot, node)
            try:
                return self.planner(self.node, node)
            except Exception as exc:
                raise NavigationFailed(f"no path to {node}: {exc}") from None
        raise NavigationFailed(f"no answer to get_path for {node}")

    async def follow(self, steps: list[PathStep]) -> None:
        """Drive along ``steps``; the first step is where the robot is."""
        if not steps:
            return
        first = steps[0]
        if self.node in (None, first.node) or not self.localized:
            self.relocalize(first)
        doors_ahead: dict[int, str] = {}  # step index -> door asked open for this pass
        called: set[tuple[str, str | None]] = set()
        try:
            i = 1
            while i < len(steps):
                self._check_fault()
                step = steps[i]
                self._ask_ahead(steps, i, doors_ahead, called)
                if step.area is not None and self._must_ask(step.area):
                    await self._acquire_area(step.area)
                prev = steps[i - 1]
                ride = (
                    step.elevator is not None
                    and prev.elevator == step.elevator
                    and prev.floor != step.floor
                )
                if ride:
                    await self._ride(prev, step)
                else:
                    await self._approach(steps, i, called)
                self.node = step.node
                self.floor = step.floor
                self.inside = step.area
                self.ep.publish(
                    NodeReached(robot=self.robot, node=step.node, floor=step.floor, at=time.time())
                )
                self._release_left(step, steps[i + 1] if i + 1 < len(steps) else None)
                self._release_passed(i, doors_ahead)
                i += 1
        finally:
            self._release_doors()
            # A path ended early (a fault, a cancel) leaves areas acquired but not entered: give
            # them back. Kept, the next path would drive in on them, though the server may have
            # released them with the task meanwhile (the soak saw a robot enter a lift granted
            # to another). Grants never used are dropped too: reporting them in robot_state
            # would claim areas the robot no longer needs.
            for area in sorted(self.held_areas - {self.inside}):
                self.held_areas.discard(area)
                log.info("%s: area %s not entered, released", self.robot, area)
                self.ep.publish(ReleaseArea(robot=self.robot, area=area))
            self._granted &= self.held_areas
        self._send_velocity(0.0, 0.0, force=True)
        self.state = NavState.IDLE

    async def _approach(
        self, steps: list[PathStep], i: int, called: set[tuple[str, str | None]]
    ) -> None:
        """Drive to step ``i``, never onto a closed door or into a cabin that is not here."""
        step = steps[i]
        cabin = (
            step.elevator is not None
            and i + 1 < len(steps)
            and steps[i + 1].elevator == step.elevator
            and steps[i + 1].floor != step.floor
        )
        while True:
            if step.area is not None and self._must_ask(step.area):
                await self._acquire_area(step.area)
            if step.door is not None:
                await self._wait_door(step.door)
            if cabin:
                assert step.elevator is not None
                await self._wait_elevator(step.elevator, step.floor, called)
            if step.area is not None and self._must_ask(step.area):
                continue  # the grant was forgotten while we waited (the link dropped): ask again
            if await self.drive_to(
                step.x, step.y, stop=i == len(steps) - 1, clear=self._passable(step, cabin)
            ):
                return
            log.warning("%s: %s not passable now, stopped before it", self.robot, step.node)
            called.discard((step.elevator or "", step.floor))
            if step.door is not None and step.door not in self._doors_open:
                self._open_door(step.door)  # closed under our hold: ask again

    def _must_ask(self, area: str) -> bool:
        """Entering ``area`` needs a grant we hold now, with the link up (docs/robot.md,
        "Link down"); the area the robot already stands in needs nothing more."""
        return area != self.inside and (area not in self.held_areas or self._link_down)

    def _passable(self, step: PathStep, cabin: bool) -> Callable[[], bool]:
        door, elevator, floor = step.door, step.elevator, step.floor
        area = step.area
        next_hold = self.clock.now() + CABIN_HOLD_CALL_S

        def clear() -> bool:
            nonlocal next_hold
            if area is not None and self._must_ask(area):
                return False
            if door is not None and door not in self._doors_open:
                return False
            if not cabin:
                return True
            if self._elevators.get(elevator or "") != floor:
                return False
            if self.clock.now() >= next_hold:
                # Driving in: call again, as a person keeps the button pressed, so the cabin
                # door does not close on the robot (the soak saw it close under one).
                next_hold = self.clock.now() + CABIN_HOLD_CALL_S
                self.ep.publish("call_elevator", {"elevator": elevator, "floor": floor})
            return True

        return clear

    def _release_passed(self, i: int, doors_ahead: dict[int, str]) -> None:
        """Doors whose node is behind the robot are let go (unless asked again further on)."""
        for index in [k for k in doors_ahead if k < i]:
            door = doors_ahead.pop(index)
            if door not in doors_ahead.values() and door in self._held_doors:
                self._held_doors.discard(door)
                log.info("%s: passed door %s, released", self.robot, door)
                self.ep.publish(ReleaseDoor(door=door))

    def _release_doors(self) -> None:
        for door in sorted(self._held_doors):
            self.ep.publish(ReleaseDoor(door=door))
        self._held_doors.clear()
        self._door_requests.clear()

    def _open_door(self, door: str) -> None:
        """Ask the building to open (and hold) ``door`` for this robot."""
        self._held_doors.add(door)
        self._door_failed.pop(door, None)
        for request, known in list(self._door_requests.items()):
            if known == door:
                del self._door_requests[request]
        message = self.ep.publish(OpenDoor(door=door))
        self._door_requests[message.id] = door

    def relocalize(self, step: PathStep, theta: float | None = None) -> None:
        """Anchor the map pose at a known node (path start, elevator exit)."""
        heading = self.theta if theta is None else theta
        ox, oy, oth = self._odom or (0.0, 0.0, 0.0)
        self._dtheta = wrap_angle(heading - oth)
        c, s = math.cos(self._dtheta), math.sin(self._dtheta)
        self._tx = step.x - (c * ox - s * oy)
        self._ty = step.y - (s * ox + c * oy)
        self.x, self.y, self.theta = step.x, step.y, heading
        self.node, self.floor = step.node, step.floor
        self.inside = step.area
        self.localized = True

    def _ask_ahead(
        self,
        steps: list[PathStep],
        i: int,
        doors_ahead: dict[int, str],
        called: set[tuple[str, str | None]],
    ) -> None:
        """Open doors and call elevators within ``lookahead_m`` of path ahead."""
        distance = math.hypot(steps[i].x - self.x, steps[i].y - self.y)
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
            ):
                called.add((s.elevator, s.floor))
                if self._elevators.get(s.elevator) != s.floor:
                    self.ep.publish("call_elevator", {"elevator": s.elevator, "floor": s.floor})
            if j + 1 < len(steps):
                distance += math.hypot(steps[j + 1].x - s.x, steps[j + 1].y - s.y)
            j += 1

    def areas_held(self) -> list[str]:
        """Areas held or granted ahead (robot_state ``areas``: the server's resync)."""
        return sorted(self.held_areas | self._granted)

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
        if stale := (self._granted | self.held_areas) - {self.inside}:
            log.info("%s: granted areas %s not entered: asked again", self.robot, sorted(stale))
            self._granted -= stale
            self.held_areas -= stale
        if self._waiting_area is not None:
            log.info("%s: still waiting for area %s: asked again", self.robot, self._waiting_area)
            self.ep.publish(RequestArea(robot=self.robot, area=self._waiting_area))
        for door in sorted(self._held_doors):
            self._open_door(door)
        if self._wait_retry is not None:
            self._wait_retry()

    async def _acquire_area(self, area: str) -> None:
        if area in self._granted and not self._link_down:
            # Granted ahead as part of a chain of back-to-back areas.
            self.held_areas.add(area)
            return
        self.state = NavState.WAITING_AREA
        self._send_velocity(0.0, 0.0)
        if area not in self._granted:
            self.ep.publish(RequestArea(robot=self.robot, area=area))
        else:
            log.warning("%s: link down: area %s is not entered until it is back", self.robot, area)
        self._waiting_area = area
        try:
            await self._wait_until(
                lambda: area in self._granted and not self._link_down, f"area {area}"
            )
        finally:
            self._waiting_area = None
        log.info("%s: area %s granted", self.robot, area)
        self.held_areas.add(area)
        self.state = NavState.MOVING

    def _release_left(self, here: PathStep, nxt: PathStep | None) -> None:
        keep = {here.area, nxt.area if nxt else None}
        for area in sorted(self.held_areas - keep):
            self.held_areas.discard(area)
            self._granted.discard(area)
            log.info("%s: left area %s, released", self.robot, area)
            self.ep.publish(ReleaseArea(robot=self.robot, area=area))

    async def _wait_door(self, door: str) -> None:
        """Stand still until the building reports ``door`` open; a refusal is an alert."""
        if door in self._doors_open:
            return
        if door not in self._held_doors:
            self._open_door(door)
        self.state = NavState.WAITING_DOOR
        self._send_velocity(0.0, 0.0, force=True)
        deadline = self.clock.now() + self.wait_timeout_s
        retry_at: float | None = None
        alerted = False
        while door not in self._doors_open:
            self._news.clear()
            self._check_fault()
            now = self.clock.now()
            reason = self._door_failed.get(door)
            if reason is not None and retry_at is None:
                self.state = NavState.DOOR_BLOCKED
                self._send_velocity(0.0, 0.0, force=True)
                log.warning("%s: door %s did not open: %s", self.robot, door, reason)
                if not alerted:
                    alerted = True
                    detail = f"door {door} did not open: {reason}"
                    self.ep.publish(
                        RobotFault(robot=self.robot, kind="door_blocked", detail=detail)
                    )
                retry_at = now + self.door_retry_s
            if now >= deadline:
                raise NavigationFailed(
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
        self.state = NavState.MOVING

    async def _wait_elevator(
        self, elevator: str, floor: str | None, called: set[tuple[str, str | None]]
    ) -> None:
        if (elevator, floor) not in called and self._elevators.get(elevator) != floor:
            self.ep.publish("call_elevator", {"elevator": elevator, "floor": floor})
        called.add((elevator, floor))
        if self._elevators.get(elevator) == floor:
            return
        self.state = NavState.WAITING_ELEVATOR
        self._send_velocity(0.0, 0.0)

        def resend() -> None:
            self.ep.publish("call_elevator", {"elevator": elevator, "floor": floor})

        await self._wait_until(
            lambda: self._elevators.get(elevator) == floor, f"elevator {elevator}", retry=resend
        )

    async def _ride(self, cabin: PathStep, exit_: PathStep) -> None:
        """In the cabin at ``cabin.floor``: send it to ``exit_.floor`` and get out there."""
        assert cabin.elevator is not None
        self.state = NavState.RIDING
        self._send_velocity(0.0, 0.0, force=True)
        self._elevators.pop(cabin.elevator, None)
        log.info("%s: riding elevator %s to floor %s", self.robot, cabin.elevator, exit_.floor)
        self.ep.publish("call_elevator", {"elevator": cabin.elevator, "floor": exit_.floor})
        elevator = cabin.elevator

        def resend() -> None:
            self.ep.publish("call_elevator", {"elevator": elevator, "floor": exit_.floor})

        await self._wait_until(
            lambda: self._elevators.get(elevator) == exit_.floor,
            f"elevator {elevator} to {exit_.floor}",
            retry=resend,
        )
        self.relocalize(exit_)
        self.state = NavState.MOVING

    async def _wait_until(
        self, ready: Callable[[], bool], what: str, *, retry: Callable[[], None] | None = None
    ) -> None:
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
                self._check_fault()
                if ready():
                    if next_log is not None:
                        waited = self.clock.now() - started
                        log.info("%s: %s came after %.0f s", self.robot, what, waited)
                    return
                now = self.clock.now()
                if next_log is None or now >= next_log:
                    if next_log is None:
                        log.info("%s: waiting for %s", self.robot, what)
                    else:
                        log.warning(
                            "%s: still waiting for %s after %.0f s (gives up after %.0f s)",
                            *(self.robot, what, now - started, self.wait_timeout_s),
                        )
                    next_log = now + WAIT_LOG_S
                if now >= deadline:
                    raise NavigationFailed(f"timed out waiting for {what}")
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

    def _check_fault(self) -> None:
        super()._check_fault()
        if self._yield is not None:
            raise self._yield
