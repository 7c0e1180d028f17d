"""Navigation: follow the Traffic Manager's path with velocity commands and odometry back.

One goal at a time (a new navigate_to pre-empts the old one). For each path the navigator
- plans it (get_path, or on board), then drives node by node over the motion control it
  inherits (robot_agent/motion.py);
- before each node asks its ``Passage`` (robot_agent/passage.py) for the restricted area, the
  door and the elevator cabin on the way, and stops before a node that is not passable;
- backs off to a passing place when the Traffic Manager asks it to yield an area, then tries
  the goal again;
- plans again when ``closures_changed`` closes a node of its path ahead (building modes, a
  jammed door, a stuck lift), and plans with the server only while any node is closed; a goal
  only closed nodes lead to fails with ``navigation_failed`` ``closed`` (a tour skips it),
  and ``trouble`` when trouble alone cuts it off (the ``path`` answer's flag: the server
  reads it from the task's task_ended, never the reason's words);
  a goal given ``trouble_wait_s`` (a tour's stop) that only trouble cuts off (a jammed door,
  a stuck lift: the server's ``path`` answer says ``trouble``) first waits that long for a
  ``closures_changed`` and plans again, so a jam of a few seconds does not cost the visitor
  the stops behind it;
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
from guidebot.payloads.petri import Docked, GoalReached, NavigationFailed, PeopleFaced
from guidebot.payloads.robot import NodeReached, RobotFault
from guidebot.payloads.traffic import AreaYield, ClosuresChanged, GetPath
from guidebot.site.steps import PathStep
from robot_agent.clock import Clock
from robot_agent.motion import MotionControl, NavigationError, NavState, wrap_angle
from robot_agent.passage import Called, Passage

__all__ = ["NavState", "NavigationError", "Navigator", "PathStep"]

log = logging.getLogger(__name__)


def _node_or_none(node: Any) -> str | None:
    """The node a request named, for its navigation_failed: a string, else none."""
    return node if isinstance(node, str) else None


class YieldRequested(Exception):
    """The Traffic Manager asks this robot to back off from an area (deadlock resolution)."""

    def __init__(self, area: str, node: str) -> None:
        super().__init__(f"yield {area}, back off to {node}")
        self.area = area
        self.node = node


class ReplanRequested(Exception):
    """A node of the path ahead was closed (closures_changed): plan the goal again."""

    def __init__(self, nodes: list[str]) -> None:
        super().__init__(f"closed ahead: {', '.join(nodes)}")
        self.nodes = nodes


class RouteClosed(NavigationError):
    """The server says only closed elements lead to the goal; ``reason`` says which and why,
    ``trouble_only`` that every closure cutting it off is trouble, none by staff (the ``path``
    answer's ``trouble`` flag: the reason is words for the visitor, never parsed)."""

    def __init__(self, reason: str, *, trouble_only: bool = False) -> None:
        super().__init__(reason)
        self.trouble_only = trouble_only


MAX_REPLANS = 8
"""Plans again for closures on the way to one goal (a closure that comes and goes)."""


class Navigator(MotionControl):
    """The on-board navigation module (an endpoint on the on-board bus): route following
    (goals, paths, yields) over the motion control it inherits; the areas, doors and
    elevators on the way are its ``passage``."""

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
        self.bumper_pause_s = bumper_pause_s
        self.path_timeout_s = path_timeout_s
        self.docking_s = docking_s
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
        self.bumps = 0
        self.yields = 0
        self._yield: YieldRequested | None = None
        self._replan: ReplanRequested | None = None
        self._backing_off: str | None = None
        """The area being yielded while the robot drives to its passing place."""
        self.step_free = False
        """Guiding a step-free tour (robot_agent/visitor_needs.py): paths over no edge with
        steps, planned by the server (its answer says when only steps lead to a goal)."""
        self.closed: frozenset[str] = frozenset()
        """Nodes closed now (closures_changed): never driven onto; plans come from the server
        while any is closed (the on-board map does not know them)."""
        self._closures_news = asyncio.Event()
        """Set by each closures_changed: a goal waiting for trouble to lift plans again."""
        self._ahead: list[str] = []
        """The nodes of the path being followed not reached yet."""
        self.replans = 0
        if (start := (position_of or {}).get(start_node or "")) is not None:
            # Odometry starts at (0, 0): anchor it at the start node until the first path.
            self._tx, self._ty = start
            self.x, self.y = start
        self._news = asyncio.Event()
        """Set when something a wait watches changes (building news, a fault, a yield)."""
        self._goal_task: asyncio.Task[None] | None = None
        self.evacuating = False
        """A fire alarm's evacuation drives the robot (robot_agent/evacuation.py): goals from
        task nets are refused until it is over."""
        self.passage = Passage(
            self,
            check=self._check_fault,
            news=self._news,
            lookahead_m=lookahead_m,
            wait_timeout_s=wait_timeout_s,
            door_retry_s=door_retry_s,
        )
        """The areas, doors and elevators on the way (what the robot knows and asked of them)."""

    @property
    def inside(self) -> str | None:
        """The restricted area of the node the robot stands on (None: outside every area)."""
        return self.passage.inside

    def areas_held(self) -> list[str]:
        """Areas held or granted ahead (robot_state ``areas``: the server's resync)."""
        return self.passage.areas_held()

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
                **self.passage.handlers(),
            },
        )
        self.on(self.ep, AreaYield, self._on_area_yield)
        self.on(self.ep, ClosuresChanged, self._on_closures)

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
        self.passage.release_doors()
        if self.state is not NavState.FAULT:
            self.state = NavState.IDLE
        self.goal = None
        self._replan = None

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
                NavigationFailed(node=_node_or_none(node), reason="navigate_to needs a node id"),
                correlation_id=message.id,
            )
            return
        wait = message.payload.get("trouble_wait_s")
        trouble_wait_s = 0.0
        if isinstance(wait, int | float) and not isinstance(wait, bool) and wait > 0:
            trouble_wait_s = float(wait)
        self._start_goal(
            self._goal(
                node, message.id, reply=GoalReached(node=node), trouble_wait_s=trouble_wait_s
            )
        )

    def _on_dock(self, message: Message) -> None:
        """The battery_charge net is at the station's node: run the docking approach."""
        station = message.payload.get("station")
        node = message.payload.get("node") or self.node
        if not isinstance(node, str) or not node:
            self.ep.publish(
                NavigationFailed(node=_node_or_none(node), reason="dock: position unknown")
            )
            return
        docked = Docked(node=node, station=station if isinstance(station, str) else None)
        self._start_goal(self._goal(node, message.id, reply=docked))

    def _on_face_people(self, message: Message) -> None:
        # Visitors follow the robot: they stand behind it. Turn around in place.
        self._start_goal(self._face_people(message.id))

    def start_evacuation(self, coro: Any) -> None:
        """Run the evacuation's drive as the goal (robot_agent/evacuation.py)."""
        self._start_goal(coro, evacuation=True)

    def _start_goal(self, coro: Any, *, evacuation: bool = False) -> None:
        if self.evacuating and not evacuation:
            coro.close()
            self.ep.publish(NavigationFailed(node=self.goal, reason="fire alarm: evacuating"))
            return
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

    def _on_area_yield(self, message: Message, ask: AreaYield) -> None:
        if ask.robot != self.robot or self._goal_task is None:
            return
        if ask.area == self._backing_off:
            return  # asked again (the server repeats a yield not acted on): already on it
        self._yield = YieldRequested(ask.area, ask.go_to_node)
        self._news.set()
        self._odom_event.set()

    def _on_closures(self, message: Message, changed: ClosuresChanged) -> None:
        if "nodes" not in message.payload:
            return  # says nothing of the nodes (the model's default is none closed)
        self.closed = frozenset(changed.nodes)
        self._closures_news.set()
        cut = [n for n in self._ahead if n in self.closed]
        if cut and self._goal_task is not None and not self.evacuating:
            log.info("%s: closed ahead (%s): planning again", self.robot, ", ".join(cut))
            self._replan = ReplanRequested(cut)
            self._news.set()
            self._odom_event.set()

    # -- goals --------------------------------------------------------------------------------

    async def _goal(
        self,
        node: str,
        request_id: str,
        *,
        reply: GoalReached | Docked,
        trouble_wait_s: float = 0.0,
    ) -> None:
        """Drive to ``node`` and answer ``reply`` (or navigation_failed); a way cut off by
        trouble alone is waited for up to ``trouble_wait_s`` (robot seconds) first."""
        self.goal = node
        self._replan = None
        try:
            yields = replans = 0
            give_up_at: float | None = None  # from the first answer that it is cut off
            backing: YieldRequested | None = None
            while True:
                try:
                    if backing is not None:  # a yield or a closure may come while backing off
                        await self._back_off(backing)
                        backing = None
                    self._closures_news.clear()  # a change from now on: plan again
                    await self.go_to(node)
                    break
                except YieldRequested as request:
                    yields += 1
                    if yields > 3:
                        raise NavigationError(
                            f"asked to yield too often on the way to {node}"
                        ) from None
                    backing = request
                except RouteClosed as cut:
                    if give_up_at is None:
                        give_up_at = self.clock.now() + trouble_wait_s
                    left = give_up_at - self.clock.now()
                    if left <= 0 or not cut.trouble_only:
                        raise
                    await self._wait_closures(left, node, cut)
                except ReplanRequested as closed:
                    replans += 1
                    self._replan = None
                    self.replans += 1
                    self._send_velocity(0.0, 0.0, force=True)
                    if replans > MAX_REPLANS:
                        raise NavigationError(
                            f"planned again too often on the way to {node} ({closed})"
                        ) from None
        except NavigationError as failure:
            self._send_velocity(0.0, 0.0, force=True)
            self.ep.publish(
                NavigationFailed(
                    node=node,
                    reason=failure.reason,
                    closed=isinstance(failure, RouteClosed),
                    trouble=isinstance(failure, RouteClosed) and failure.trouble_only,
                ),
                correlation_id=request_id,
            )
            return
        finally:
            self.goal = None
        log.info("%s: reached %s", self.robot, node)
        if isinstance(reply, Docked):
            await self.clock.sleep(self.docking_s)  # the final approach onto the contacts
        self.ep.publish(reply, correlation_id=request_id)

    async def _wait_closures(self, left_s: float, node: str, cut: RouteClosed) -> None:
        """Stand still until the closures change (trouble lifted: plan again) or ``left_s``
        robot seconds have passed (then the goal is planned once more and, still cut off,
        fails ``closed``)."""
        self._send_velocity(0.0, 0.0, force=True)
        log.info("%s: %s cut off (%s): waiting up to %.0f s", self.robot, node, cut.reason, left_s)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self.clock.wall(left_s)):
                await self._closures_news.wait()

    async def _back_off(self, request: YieldRequested) -> None:
        """Leave the area for its passing place, give it up, then the goal is tried again."""
        self.yields += 1
        self._yield = None
        self._send_velocity(0.0, 0.0, force=True)
        log.info("%s: yielding area %s, backing off to %s", self.robot, request.area, request.node)
        self._backing_off = request.area
        try:
            if request.node and request.node != self.node:
                await self.go_to(request.node)
        finally:
            self._backing_off = None
        self.passage.give_up(request.area)

    async def _face_people(self, request_id: str) -> None:
        with contextlib.suppress(NavigationError):
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
        if (
            self.plan_on_board
            and not self.closed
            and not self.step_free
            and self.planner is not None
            and self.node is not None
        ):
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
                    GetPath(
                        robot=self.robot,
                        from_node=self.node,
                        to_node=node,
                        step_free=self.step_free,
                    ),
                    timeout=self.path_timeout_s,
                )
            except RequestTimeout:
                log.warning("%s: no path to %s yet (attempt %d)", self.robot, node, attempt + 1)
                continue
            if reply.type == "path" and reply.payload.get("closed"):
                raise RouteClosed(
                    str(reply.payload.get("reason") or f"{node} is closed"),
                    trouble_only=reply.payload.get("trouble") is True,
                )
            if reply.type != "path" or not reply.payload.get("steps"):
                reason = reply.payload.get("error") or reply.payload.get("reason") or reply.payload
                raise NavigationError(f"no path to {node}: {reason}")
            return reply.payload
        if self.planner is not None and self.node is not None and not self.step_free:
            # The link is down: plan on the on-board map and go on alone (areas, doors and
            # elevators still wait for the server's answers).
            log.warning("%s: Traffic Manager silent, planning to %s on board", self.robot, node)
            try:
                return self.planner(self.node, node)
            except Exception as exc:
                raise NavigationError(f"no path to {node}: {exc}") from None
        raise NavigationError(f"no answer to get_path for {node}")

    async def follow(self, steps: list[PathStep]) -> None:
        """Drive along ``steps``; the first step is where the robot is."""
        if not steps:
            return
        first = steps[0]
        if self.node in (None, first.node) or not self.localized:
            self.relocalize(first)
        doors_ahead: dict[int, str] = {}  # step index -> door asked open for this pass
        called: Called = set()
        passage = self.passage
        passage.new_path()
        try:
            i = 1
            while i < len(steps):
                self._ahead = [s.node for s in steps[i:]]
                self._check_fault()
                step = steps[i]
                passage.ask_ahead(steps, i, doors_ahead, called)
                if step.area is not None and passage.must_ask(step.area):
                    await passage.acquire_area(step.area)
                prev = steps[i - 1]
                ride = (
                    step.elevator is not None
                    and prev.elevator == step.elevator
                    and prev.floor != step.floor
                )
                if ride:
                    await passage.ride(prev, step)
                    self.relocalize(step)
                    self.state = NavState.MOVING
                else:
                    await self._approach(steps, i, called)
                self.node = step.node
                self.floor = step.floor
                passage.inside = step.area
                passage.edge_areas.clear()
                self.ep.publish(
                    NodeReached(robot=self.robot, node=step.node, floor=step.floor, at=time.time())
                )
                passage.release_left(step, steps[i + 1] if i + 1 < len(steps) else None)
                passage.release_passed(i, doors_ahead)
                i += 1
        finally:
            self._ahead = []
            passage.release_doors()
            passage.release_not_entered()
        self._send_velocity(0.0, 0.0, force=True)
        self.state = NavState.IDLE

    async def _approach(self, steps: list[PathStep], i: int, called: Called) -> None:
        """Drive to step ``i``, never onto a closed door or into a cabin that is not here, and
        out of a cabin only while it stands open at its floor (called there to keep its door
        open, as a person presses the button; not while evacuating: the fire alarm refuses
        calls, and the robot gets out where the cabin stopped, docs/emergency.md)."""
        step = steps[i]
        cabin = (
            step.elevator is not None
            and i + 1 < len(steps)
            and steps[i + 1].elevator == step.elevator
            and steps[i + 1].floor != step.floor
        )
        prev = steps[i - 1]
        leaving = prev if prev.elevator is not None and step.elevator != prev.elevator else None
        passage = self.passage
        while True:
            if step.area is not None and passage.must_ask(step.area):
                await passage.acquire_area(step.area)
            if step.door is not None:
                await passage.wait_door(step.door)
            if cabin:
                assert step.elevator is not None
                await passage.wait_elevator(step.elevator, step.floor, called)
            out_of = None if self.evacuating else leaving
            if out_of is not None:
                assert out_of.elevator is not None
                await passage.wait_elevator(out_of.elevator, out_of.floor, called)
            if step.area is not None and passage.must_ask(step.area):
                continue  # the grant was forgotten while we waited (the link dropped): ask again
            if step.area is not None:
                passage.edge_areas.add(step.area)  # from here on it may be inside
            clear = passage.passable(step, cabin, leaving=out_of)
            if await self.drive_to(step.x, step.y, stop=i == len(steps) - 1, clear=clear):
                return
            log.warning("%s: %s not passable now, stopped before it", self.robot, step.node)
            passage.stopped_before(step, called)

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
        self.passage.inside = step.area
        self.localized = True

    def link_lost(self) -> None:
        """The link is down: doors and cabins become unknown (Passage.link_lost)."""
        self.passage.link_lost()

    def resync(self) -> None:
        """The link is back: ask again for what the robot waits for (Passage.resync)."""
        self.passage.resync()

    def _check_fault(self) -> None:
        super()._check_fault()
        if self._yield is not None:
            raise self._yield
        if self._replan is not None:
            raise self._replan
