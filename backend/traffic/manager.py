"""The Traffic Manager: answers get_path, grants restricted areas, watches robots' positions.

A plain asyncio-free service over a bus endpoint: every handler runs inline and returns fast.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from backend.alerts import AlertStore
from backend.closure import Closure
from backend.detours import RouteClosed, path_avoiding, step_free_path_of
from backend.traffic.locks import AreaLocks, Cut, Grant, LockError, LockView, Yield
from backend.traffic.restarts import BootIds, release_former_holds
from backend.traffic.whereabouts import areas_near, claimed_areas
from guidebot.bus import BusEndpoint
from guidebot.delivery import courier_for, listen
from guidebot.messages import Message, make_message
from guidebot.payloads.hub import Error
from guidebot.payloads.robot import NodeReached, RobotMode, RobotState
from guidebot.payloads.tasks import RobotLink, TaskEnded, TaskEvent
from guidebot.payloads.traffic import AreaGranted, AreaYield, GetPath, ReleaseArea, RequestArea
from guidebot.service import Service
from guidebot.site.graph import NoPath, PathResult, SiteGraph, UnknownNode
from guidebot.site.schema import Site

__all__ = ["TrafficManager"]

log = logging.getLogger(__name__)

FINAL_TASK_STATES = frozenset({"done", "failed", "cancelled"})
EventSink = Callable[[str, dict[str, Any]], None]

CYCLE_BREAK_S = 20.0
"""A robot asked to back off (a cycle of waits) that still holds the area after this long is
asked again; after twice this long another robot of the cycle backs off instead. A cycle
never lasts 60 s (issue 36): the first word at once, the second at 20 s, another robot at 40 s."""
CYCLE_CHECK_S = 1.0
"""How often the lock table is looked at for cycles and yields not acted on."""


@dataclass(slots=True)
class _YieldWatch:
    """A yield asked of a robot, until it lets the area go."""

    since: float
    cycle: tuple[str, ...]
    wanted: tuple[str, ...]
    asked_again: bool = False
    escalated: bool = False


class TrafficManager(Service):
    """Paths and area locks for one site; ``load_site`` swaps the map while running."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        site: Site,
        *,
        graph: SiteGraph | None = None,
        on_event: EventSink | None = None,
        alerts: AlertStore | None = None,
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.on_event = on_event
        self.alerts = alerts if alerts is not None else AlertStore(endpoint.publish)
        self._positions: dict[str, str] = {}
        self._position_at: dict[str, float] = {}
        """Robot -> the time (Unix s) of the report that last moved its position (a
        node_reached's ``at``, a robot_state's ``timestamp``): a ``node_reached`` sent again
        after a drop (must-arrive) never moves it back."""
        self._paths: dict[str, PathResult] = {}
        self.site = site
        self.graph = graph or SiteGraph(site)
        self.locks = AreaLocks([a.id for a in site.areas])
        self._robots = {r.name for r in site.robots}
        self._removed: dict[str, int] = {}
        """Areas a publish removed -> the site version without them: a robot that asks for
        one (its path was planned on the old site) is told so at once, not refused."""
        self.boots = BootIds()
        """Each robot's agent process (robot_state ``boot_id``): a new one drops old holds."""
        # After a restart: robots that may hold locks, whose word comes before any grant.
        self._awaiting: set[str] = set()
        self._deferred: list[Message] = []
        self._declared: set[str] = set()
        """Robots whose first robot_state (their declaration of locks) was taken."""
        self._resync_timer: asyncio.TimerHandle | None = None
        self.courier = courier_for(endpoint)
        """area_granted: sent again until the robot acknowledges it."""
        self.gate: Callable[[str, str], str | None] | None = None
        """Asked with (robot, area) before a grant: a reason to refuse (the fire alarm holds
        the area and it is not on the robot's way to safety, backend.emergency), or None."""
        self.closures: Callable[[], Mapping[str, Closure]] | None = None
        """The nodes closed now (building modes and trouble, backend.closures): paths avoid
        them, and a goal only they lead to is refused with their reasons."""
        self.cycle_break_s = CYCLE_BREAK_S
        self._yields: dict[tuple[str, str], _YieldWatch] = {}
        self._kept: dict[str, set[str]] = {}
        """Areas kept at a task's end because the robot may be inside them (whereabouts.py):
        released once the robot's own word shows it is not (``_on_robot_state``)."""
        self._ending: dict[str, str] = {}
        """robot -> a task the server ended (a cancel, a preemption) that the robot may still
        be running: until it reports otherwise, it may drive on with every area it holds."""
        self._reported_end: dict[str, str] = {}
        """robot -> the last task whose end it reported itself (task_ended)."""

    # --- life cycle ----------------------------------------------------------------------
    async def on_start(self) -> None:
        ep = self.endpoint
        # Requests answer a payload that is not their model (an in-process sender's mistake)
        # with an error reply, so they read it themselves (``msg.typed``: validated once).
        self.subscribe_all(
            ep,
            {
                "get_path": self._on_get_path,
                "request_area": self._on_request_area,
                "release_area": self._on_release_area,
            },
        )
        self.on(ep, RobotState, self._on_robot_state)
        self.on(ep, TaskEnded, self._on_task_ended)
        self.on(ep, TaskEvent, self._on_task_event)
        self.on(ep, NodeReached, self._on_node_reached)
        self.on(ep, RobotLink, self._on_robot_disconnected, types=["robot_disconnected"])
        for unsubscribe in listen(self.endpoint, self.courier):
            self.on_cleanup(unsubscribe)
        self.spawn(self._watch_cycles(), name="traffic-wait-cycles")

    async def _watch_cycles(self) -> None:
        while True:
            await asyncio.sleep(min(CYCLE_CHECK_S, self.cycle_break_s / 4))
            try:
                self.check_wait_cycles()
            except Exception:
                log.exception("traffic: the wait-cycle check failed")

    async def on_stop(self) -> None:
        self.courier.close()
        if self._resync_timer is not None:
            self._resync_timer.cancel()
            self._resync_timer = None

    def await_resync(self, robots: set[str], timeout_s: float) -> None:
        """A restart: the lock table is empty, and ``robots`` (those that had a task) may
        hold areas. Area requests wait until each has sent its robot_state (which declares
        what it holds) or ``timeout_s`` has passed, so that no area is granted over a robot
        inside it that reconnects a second later (found by the soak)."""
        self._awaiting = set(robots) & self._robots
        if not self._awaiting:
            return
        log.warning(
            "traffic: no area granted until %s report(s) what they hold (at most %g s)",
            ", ".join(sorted(self._awaiting)),
            timeout_s,
        )
        loop = asyncio.get_running_loop()
        self._resync_timer = loop.call_later(timeout_s, self._end_resync)

    def restore_locks(self, holders: Mapping[str, str]) -> None:
        """A restart: the locks held when the last server life ended (area -> robot, from the
        event log) are held again, by robots offline until they report, as if entered. A robot
        inside an area whose link is still down when the resync window ends would otherwise
        find another robot granted its area. Its first ``robot_state`` releases what it is
        not in; one that never comes back leaves its locks to staff (offline grace)."""
        for area, robot in sorted(holders.items()):
            if area not in self.graph.area_nodes or robot not in self._robots:
                continue
            self.locks.set_online(robot, False)
            if self.locks.adopt(robot, area, entered=True):
                log.warning("traffic: %s holds %s since the last server life", robot, area)
                self._emit("area_granted", {"robot": robot, "area": area, "restored": True})

    def _end_resync(self) -> None:
        if self._resync_timer is not None:
            self._resync_timer.cancel()
            self._resync_timer = None
        if self._awaiting:
            log.warning(
                "traffic: resync over without word from %s", ", ".join(sorted(self._awaiting))
            )
        self._awaiting.clear()
        deferred, self._deferred = self._deferred, []
        for msg in deferred:
            self._on_request_area(msg)

    def load_site(self, site: Site, graph: SiteGraph | None = None) -> None:
        """New map, same locks: areas that still exist keep holder, state and waiters; robots
        waiting for an area the new site lacks are told at once (``area_granted`` with
        ``removed``) and go on, or keep waiting for the rest of their chain."""
        old_areas = set(self.locks.areas)
        self.site = site
        self.graph = graph or SiteGraph(site)
        self._robots = {r.name for r in site.robots}
        self._paths.clear()
        new_areas = [a.id for a in site.areas]
        for area in new_areas:
            self._removed.pop(area, None)
        for area in old_areas - set(new_areas):
            self._removed[area] = site.version
        cuts, grants = self.locks.reshape(new_areas)
        for cut in cuts:
            self._tell_removed(cut)
        self._send_grants(grants)

    def _tell_removed(self, cut: Cut) -> None:
        for area in cut.areas:
            reason = f"area {area} is not on the site any more (version {self._removed[area]})"
            log.info("traffic: %s no longer waits for %s: %s", cut.robot, area, reason)
            self.courier.post(
                make_message(
                    AreaGranted(robot=cut.robot, area=area, removed=True, reason=reason),
                    source=self.endpoint.name,
                    destination=cut.robot,
                    correlation_id=cut.request_id,
                ),
                key=(cut.robot, area),
            )
            self._emit("area_removed", {"robot": cut.robot, "area": area, "reason": reason})

    # --- queries used by the API ---------------------------------------------------------
    def path(self, start: str, goal: str, *, step_free: bool = False) -> PathResult:
        """The shortest open path (RouteClosed when closures cut the goal off); ``step_free``:
        over no edge with steps (StepsOnly when only steps lead there)."""
        closed = self.closures() if self.closures is not None else {}
        found = path_avoiding(self.graph, start, goal, closed)
        return step_free_path_of(self.graph, found, closed) if step_free else found

    def lock_views(self) -> list[LockView]:
        return self.locks.view()

    def force_release(self, area: str, *, by: str) -> str | None:
        """Staff release of an area lock; returns the robot that held it."""
        holder, grants = self.locks.force_release(area)
        if holder is not None:
            self.courier.withdraw((holder, area))
        self._emit("area_force_released", {"area": area, "robot": holder, "by": by})
        self.alerts.resolve("lock_holder_offline", area, f"area {area} released by {by}")
        self._send_grants(grants)
        return holder

    def check_offline_locks(self, grace_s: float, now: float | None = None) -> None:
        """Locks of robots offline for ``grace_s``: released if the robot was never inside,
        kept (it may be inside) with a staff alert otherwise (docs/server.md, "Lock policy")."""
        now = time.monotonic() if now is None else now
        decided, grants = self.locks.expire_offline(now, grace_s, self._may_be_inside)
        for d in decided:
            if d.released:
                self.alerts.raise_(
                    "lock_released_offline",
                    d.area,
                    f"area {d.area} released: {d.robot} went offline {d.offline_s:.0f} s ago "
                    "and was never seen inside it or at its edge",
                    "warning",
                    lasting=False,
                )
                self._emit("area_released", {"robot": d.robot, "area": d.area, "offline": True})
            else:
                self.alerts.raise_(
                    "lock_holder_offline",
                    d.area,
                    f"area {d.area} stays locked: {d.robot} has been offline {d.offline_s:.0f} s "
                    "and may be inside; check the area, then release it by hand",
                )
        self._send_grants(grants)

    def check_wait_cycles(self, now: float | None = None) -> None:
        """Run-time guard (issue 36: no robot waits 60 s in a cycle the server does not break).
        A cycle in the wait-for graph that the request-time rule did not see (formed by a
        resync, a restored lock, a publish) is broken at once; a robot asked to back off that
        still holds the area after ``cycle_break_s`` is asked again, and after twice that
        another robot of the cycle backs off instead (the first may be stuck, or deaf)."""
        now = time.monotonic() if now is None else now
        for cycle in self.locks.cycles():
            victim = self.locks.newest_waiter(cycle)
            self.locks.deadlocks_resolved += 1
            yields = self.locks.ask_to_yield(victim, cycle)
            self._cycle_alert(cycle, f"{victim} backs off")
            self._send_yields(yields, now)
        held = set(self.locks.yielding())
        for key in [k for k in self._yields if k not in held]:
            del self._yields[key]
        for (robot, area), watch in list(self._yields.items()):
            age = now - watch.since
            if age >= 2 * self.cycle_break_s and not watch.escalated:
                watch.escalated = True
                self._escalate(robot, area, watch, now)
            elif age >= self.cycle_break_s and not watch.asked_again:
                watch.asked_again = True
                yields = self.locks.ask_to_yield(
                    robot, list(watch.cycle), again=True, areas=(area,)
                )
                self._cycle_alert(
                    list(watch.cycle), f"{robot} asked again to back off from {area} ({age:.0f} s)"
                )
                self._send_yields(yields, now)

    def _escalate(self, robot: str, area: str, watch: _YieldWatch, now: float) -> None:
        """``robot`` did not back off from ``area``: the holders of what it waited for back off
        instead, and it waits for those areas again in its old place."""
        others = {
            h: tuple(a for a in watch.wanted if self.locks.holder(a) == h)
            for a in watch.wanted
            if (h := self.locks.holder(a)) is not None and h != robot
        }
        yields: list[Yield] = []
        for other, areas in sorted(others.items()):
            yields += self.locks.ask_to_yield(other, list(watch.cycle), areas=areas)
        if not yields:
            return
        grants, more = self.locks.request(robot, watch.wanted)
        names = ", ".join(sorted(others))
        self._cycle_alert(
            list(watch.cycle), f"{robot} did not back off from {area}: {names} back(s) off instead"
        )
        self._send_yields(yields + more, now)
        self._send_grants(grants)

    def _cycle_alert(self, cycle: list[str], what: str) -> None:
        text = f"cycle of waits {' -> '.join([*cycle, cycle[0]])}: {what}"
        log.warning("traffic: %s", text)
        self.alerts.raise_("wait_cycle", "+".join(sorted(cycle)), text, "warning", lasting=False)
        self._emit("wait_cycle_broken", {"cycle": list(cycle), "what": what})

    def _may_be_inside(self, robot: str, area: str) -> bool:
        """Last seen inside the area, or at its edge (a node one step from it): a robot
        granted the area there may have driven in after its link dropped. Robots never enter
        a granted area while their link is down (docs/robot.md), so a holder last seen
        farther away is outside."""
        node = self._positions.get(robot, "")
        at = self.graph.area_at
        if at.get(node) == area:
            return True
        return any(at.get(n) == area for n, _ in self.graph.adj.get(node, ()))

    # --- handlers ------------------------------------------------------------------------
    def _on_get_path(self, msg: Message) -> None:
        try:
            req: GetPath = msg.typed(GetPath)
        except ValidationError as exc:
            self._reply(msg, "path", {"error": f"bad get_path: {exc.errors()[0]['msg']}"})
            return
        robot = self._robot_of(msg, req.robot)
        start = req.from_node or self._positions.get(robot or "")
        try:
            if start is None:
                raise UnknownNode("the robot's position is unknown: give from_node")
            result = self.path(start, req.to_node, step_free=req.step_free)
        except RouteClosed as exc:
            log.info("traffic: no open path for %s to %s: %s", robot, req.to_node, exc.reason)
            refusal = {"error": str(exc), "closed": True, "reason": exc.reason}
            self._reply(msg, "path", refusal | {"trouble": exc.trouble})
            return
        except (UnknownNode, NoPath) as exc:
            self._reply(msg, "path", {"error": str(exc).strip("'\"")})
            return
        if robot:
            self._paths[robot] = result
        self._reply(
            msg,
            "path",
            {
                "nodes": result.nodes,
                "length_m": result.length_m,
                "steps": [s.as_dict() for s in result.steps],
            },
        )

    def _on_request_area(self, msg: Message) -> None:
        try:
            req: RequestArea = msg.typed(RequestArea)
        except ValidationError:
            return self._refuse(msg, "bad request_area payload")
        robot = self._robot_of(msg, req.robot)
        if robot is None:
            return self._refuse(msg, f"{msg.source} may not ask for areas as {req.robot}")
        if self._awaiting:
            log.info(
                "traffic: %s waits for %s until %s have resynced",
                robot,
                req.area,
                ", ".join(sorted(self._awaiting)),
            )
            self._deferred.append(msg)
            return
        if req.area in self._removed and req.area not in self.graph.area_nodes:
            self._tell_removed(Cut(robot, (req.area,), msg.id, still_waiting=False))
            return
        chain = self._chain(robot, req.area)
        if self.gate is not None:
            for area in chain:
                if (why := self.gate(robot, area)) is not None:
                    return self._refuse(msg, why)
        try:
            grants, yields = self.locks.request(robot, chain, msg.id)
        except LockError as exc:
            return self._refuse(msg, str(exc))
        self._emit("area_requested", {"robot": robot, "area": req.area, "chain": list(chain)})
        self._send_grants(grants)
        self._send_yields(yields, time.monotonic())
        self._log_wait(robot)

    def _log_wait(self, robot: str) -> None:
        """Say what a robot now waits for and who holds it (offline holders at warning)."""
        waiting = self.locks.waiting_for(robot)
        if not waiting:
            return
        holders = {a: self.locks.holder(a) for a in waiting}
        offline = sorted(h for h in holders.values() if h and not self.locks.is_online(h))
        what = ", ".join(
            f"{a} (held by {h or 'nobody; an earlier waiter goes first'})"
            for a, h in holders.items()
        )
        if offline:
            log.warning(
                "traffic: %s waits for %s; offline holder: %s", robot, what, ", ".join(offline)
            )
        else:
            log.info("traffic: %s waits for %s", robot, what)

    def _on_release_area(self, msg: Message) -> None:
        try:
            req: ReleaseArea = msg.typed(ReleaseArea)
        except ValidationError:
            return self._refuse(msg, "bad release_area payload")
        robot = self._robot_of(msg, req.robot)
        if robot is None:
            return self._refuse(msg, f"{msg.source} may not release areas of {req.robot}")
        try:
            grants = self.locks.release(robot, req.area)
        except LockError as exc:
            return self._refuse(msg, str(exc))
        self.courier.withdraw((robot, req.area))  # a grant still in flight is not news
        self._emit("area_released", {"robot": robot, "area": req.area})
        self._send_grants(grants)

    def _on_robot_state(self, msg: Message, state: RobotState) -> None:
        robot, node = state.robot, state.node
        if self._robot_of(msg, robot) is None:
            return
        known = node is not None and node in self.graph
        if known and (previous := self.boots.restarted(robot, state.boot_id)):
            self._restarted(robot, str(node), previous)
        online = state.mode != RobotMode.OFFLINE
        if online and not self.locks.is_online(robot):
            for area in self.locks.held_by(robot):
                self.alerts.resolve(
                    "lock_holder_offline", area, f"{robot} is back online; it holds {area}"
                )
        self.locks.set_online(robot, online)
        here = self.graph.area_at.get(node) if node is not None and known else None
        # ``areas`` left out (an older agent, an in-process vehicle) is not ``[]``: it says
        # nothing (whereabouts.py), so it is read from the JSON, where absence shows.
        reported = state.areas if "areas" in msg.payload else None
        self._adopt(robot, here, reported)
        if robot in self._awaiting:
            self._awaiting.discard(robot)
            if not self._awaiting:
                self._end_resync()
        if node is None or not known:
            return
        if self._positions.get(robot) != node:
            # Further on than its node_reached said (one lost): a copy of that one sent again
            # later is older. A state naming the node it already has moves nothing: the time
            # stays that of the node_reached (a VDA vehicle's is its own clock, not ours).
            self._positions[robot] = node
            self._position_at[robot] = max(msg.timestamp, self._position_at.get(robot, 0.0))
        self._check_conflict(robot, here)
        if self._ending.get(robot) not in (None, state.task_id):
            del self._ending[robot]  # it runs something else now: the ended task is over
        moving = bool(state.task_id)
        self._release_left(robot, here, moving, claimed_areas(reported))

    def _on_node_reached(self, msg: Message, reached: NodeReached) -> None:
        """Each node the robot reaches (between its robot_state reports, a second apart): its
        position, and an area it is now inside."""
        robot, node = reached.robot, reached.node
        if self._robot_of(msg, robot) is None or node not in self.graph:
            return
        at = float(reached.at) if reached.at is not None else msg.timestamp
        if at >= self._position_at.get(robot, 0.0):
            # An older one (sent again after a drop) is history: the robot is further on.
            self._positions[robot] = node
            self._position_at[robot] = at
        if (here := self.graph.area_at.get(node)) is not None:
            self.locks.mark_entered(robot, here)

    def _release_left(
        self, robot: str, here: str | None, moving: bool, claims: set[str] | None
    ) -> None:
        """A robot_state: the areas the robot has surely left go. Only an area it entered or
        one kept at a task's end, and never while it may still run a task the server ended.
        A robot with no task stands still: out of an area is out. One on a task (``moving``)
        may be on the edge into an area next to it (whereabouts.py): that one goes only if
        the robot does not claim it (robot_state ``areas``: it asks before entering). One
        kept at a task's end goes while the robot stands only if it no longer claims it (a
        VDA 5050 vehicle cancelled on an edge stands there, its last node behind it: the
        master control claims the area until the vehicle's position shows it out)."""
        running_ended = robot in self._ending
        kept = self._kept.get(robot, set())
        near: set[str] | None = None
        grants: list[Grant] = []
        for area in self.locks.held_by(robot):
            if area == here:
                self.locks.mark_entered(robot, area)
                continue
            if running_ended or not (self.locks.entered(area) or area in kept):
                continue
            if moving:
                near = self._may_be_in(robot) if near is None else near
                if area in near and (claims is None or area in claims):
                    continue
            elif area in kept and claims is not None and area in claims:
                continue  # stopped on the edge into it (a VDA 5050 vehicle): its word lets go
            kept.discard(area)
            grants += self.locks.release(robot, area)
            self.courier.withdraw((robot, area))
            self._emit("area_released", {"robot": robot, "area": area, "left": True})
        self._send_grants(grants)

    def _on_task_ended(self, msg: Message, ended: TaskEnded) -> None:
        if ended.outcome == "refused":
            return  # a task it did not take: the one it runs keeps its areas
        robot = ended.robot
        if self._robot_of(msg, robot) is not None:
            self._reported_end[robot] = ended.task_id
            self._ending.pop(robot, None)
            self._task_over(robot)

    def _on_task_event(self, msg: Message, event: TaskEvent) -> None:
        robot, task = event.robot, event.task_id
        if event.state not in FINAL_TASK_STATES or robot is None:
            return
        if self._reported_end.get(robot) == task:
            self._task_over(robot)  # the robot said so itself: it has stopped
        else:
            self._task_ending(robot, task)

    def _on_robot_disconnected(self, msg: Message, link: RobotLink) -> None:
        self.locks.set_online(link.robot, False)

    # --- helpers -------------------------------------------------------------------------
    def _restarted(self, robot: str, node: str, previous: str) -> None:
        """A new agent process under a known name (the old one is gone): its holds and queue
        place go at once, but for the area the robot reports being inside (restarts.py)."""
        done = release_former_holds(self.locks, robot, self.graph.area_at.get(node))
        self._kept.pop(robot, None)  # the new process's word is its own (restarts.py)
        self._ending.pop(robot, None)
        self._declared.discard(robot)  # its first word is a declaration, as after our restart
        why = f"{robot}'s agent restarted (the process that held it is gone) and reports {node}"
        for area in done.released + done.kept:
            self.courier.withdraw((robot, area))
        for area in done.released:
            self.alerts.resolve("lock_holder_offline", area, f"area {area} released: {why}")
            reason = f"{why}, outside {area}"
            self._emit("area_released", {"robot": robot, "area": area, "reason": reason})
        log.warning("traffic: %s; released %s", why, ", ".join(done.released) or "nothing")
        self._emit(
            "robot_restarted",
            {
                "robot": robot,
                "node": node,
                "released": done.released,
                "kept": done.kept,
                "previous_boot_id": previous,
            },
        )
        self._send_grants(done.grants)

    def _adopt(self, robot: str, here: str | None, reported: object) -> None:
        """The locks a robot says it holds (robot_state ``areas``) and the area it stands in
        are its own: after a server restart this lock table starts empty, and without this a
        second robot would be granted an area the first is in (found by the soak)."""
        if robot in self._declared:
            return  # only a robot's first word after this server started: later, this table
            # is the truth and a stale claim (a grant its task no longer needs) is not taken
        self._declared.add(robot)
        claimed = [a for a in reported if isinstance(a, str)] if isinstance(reported, list) else []
        if here is not None:
            claimed.append(here)
        for area in dict.fromkeys(claimed):
            if area not in self.graph.area_nodes or self.locks.holder(area) == robot:
                continue
            if self.locks.adopt(robot, area, entered=area == here):
                log.warning("traffic: %s holds %s by its own report (resync)", robot, area)
                self._emit("area_granted", {"robot": robot, "area": area, "resync": True})

    def _check_conflict(self, robot: str, here: str | None) -> None:
        """A robot reporting itself inside an area another robot holds: tell staff at once."""
        holder = self.locks.holder(here) if here else None
        if here is not None and holder is not None and holder != robot:
            if not self.alerts.is_active("area_conflict", robot):
                self.alerts.raise_(
                    "area_conflict",
                    robot,
                    f"{robot} reports being in area {here}, which {holder} holds",
                )
        else:
            self.alerts.resolve(
                "area_conflict", robot, f"{robot} is no longer in an area another robot holds"
            )

    def _may_be_in(self, robot: str) -> set[str]:
        """The areas the robot may be inside: its last node's and its next node's."""
        node = self._positions.get(robot)
        return areas_near(self.graph, node, self._paths.get(robot))

    def _task_over(self, robot: str) -> None:
        """The robot ended its task (it has stopped): its locks go, but for the areas it may
        be inside (its last node's, and its next node's: it may have stopped on the edge),
        kept until its robot_state shows it out of them (``_release_left``)."""
        keep = self._may_be_in(robot)
        held = self.locks.held_by(robot)
        grants = self.locks.release_all(robot, keep=keep)
        self._paths.pop(robot, None)
        kept = self._kept.setdefault(robot, set())
        for area in held:
            if area in keep:
                kept.add(area)
            else:
                kept.discard(area)
                self.courier.withdraw((robot, area))
                self._emit("area_released", {"robot": robot, "area": area, "task_ended": True})
        self._send_grants(grants)

    def _task_ending(self, robot: str, task: str) -> None:
        """The server ended a task (a cancel, a preemption, a robot lost) that the robot may
        still be driving: until it stops (its task_ended) or shows it runs something else
        (robot_state), it may drive on into any area it was granted, so every one is kept;
        only its wait for more is dropped (the soak saw a robot drive on through a corridor
        released at its preempted charge's end, granted meanwhile to another robot)."""
        self._ending[robot] = task
        self._kept.setdefault(robot, set()).update(self.locks.held_by(robot))
        self._send_grants(self.locks.cancel_wait(robot))

    def _chain(self, robot: str, area: str) -> tuple[str, ...]:
        """The areas the robot's known path crosses back to back from ``area`` (prevention)."""
        path = self._paths.get(robot)
        if path is None:
            return (area,)
        steps = path.steps
        for i, step in enumerate(steps):
            if step.area == area:
                chain = [area]
                for nxt in steps[i + 1 :]:
                    if nxt.area is None:
                        break
                    if nxt.area != chain[-1]:
                        chain.append(nxt.area)
                return tuple(dict.fromkeys(chain))
        return (area,)

    def _robot_of(self, msg: Message, claimed: str) -> str | None:
        """A robot speaks only as itself; in-process modules may speak for any robot."""
        if msg.source in self._robots and msg.source != claimed:
            return None
        return claimed or (msg.source if msg.source in self._robots else None)

    def _send_grants(self, grants: list[Grant]) -> None:
        for g in grants:
            self._kept.get(g.robot, set()).discard(g.area)  # its own again, for a new path
            granted = make_message(
                AreaGranted(robot=g.robot, area=g.area),
                source=self.endpoint.name,
                destination=g.robot,
                correlation_id=g.request_id,
            )
            self.courier.post(granted, key=(g.robot, g.area))
            again = {"again": True} if g.again else {}
            self._emit("area_granted", {"robot": g.robot, "area": g.area, **again})

    def _send_yields(self, yields: list[Yield], now: float) -> None:
        for y in yields:
            watch = self._yields.get((y.robot, y.area))
            if watch is None:
                self._yields[(y.robot, y.area)] = _YieldWatch(now, y.cycle, y.wanted)
            near = [self._positions[y.robot]] if y.robot in self._positions else []
            go_to = self.graph.passing_place_for(y.area, near) or ""
            self.endpoint.publish(
                AreaYield(robot=y.robot, area=y.area, go_to_node=go_to),
                destination=y.robot,
            )
            self._emit(
                "deadlock_resolved",
                {"robot": y.robot, "area": y.area, "cycle": list(y.cycle), "go_to_node": go_to},
            )

    def _refuse(self, msg: Message, reason: str) -> None:
        log.info("traffic: refused %s from %s: %s", msg.type, msg.source, reason)
        self.endpoint.reply(msg, Error(code="refused", reason=reason, message_id=msg.id))

    def _reply(self, msg: Message, type_: str, payload: dict[str, Any]) -> None:
        self.endpoint.send(msg.reply(type_, payload))

    def _emit(self, kind: str, data: dict[str, Any]) -> None:
        if self.on_event is not None:
            self.on_event(kind, data)
