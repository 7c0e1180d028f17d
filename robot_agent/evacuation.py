"""The robot's part of a fire alarm (docs/emergency.md): on ``evacuate``, stop, drop the task,
say the site's words, let go of doors, drive to the safe spot; report each stage.

Order matters: the first thing on the CAN bus after the order arrives is a zero-velocity
command, before the task's net is killed or anything is said. The way comes from the server
(``steps``: no elevator, no door asked for, no escape route entered); the areas on it are asked
for as on any path, and the Traffic Manager grants them to a robot on its way to safety.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.emergency import EmergencyChanged, EvacuationState, EvacuationStateName
from guidebot.payloads.petri import Say
from guidebot.payloads.robot import NodeReached
from guidebot.payloads.tasks import TaskAssigned
from guidebot.service import Service
from guidebot.site.steps import PathStep
from robot_agent.motion import NavigationError
from robot_agent.navigation import Navigator, YieldRequested
from robot_agent.tasks import TaskRunner

__all__ = ["CUT_OFF", "Evacuation"]

log = logging.getLogger(__name__)

CUT_OFF = "fire alarm"
ATTEMPTS = 3
RETRY_S = 5.0
"""Robot seconds between two tries of a robot stuck on its way to safety."""


class Evacuation(Service):
    """Follows ``evacuate`` and ``emergency_changed`` on the on-board bus."""

    def __init__(
        self, endpoint: Endpoint, robot: str, navigator: Navigator, tasks: TaskRunner
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.navigator = navigator
        self.tasks = tasks
        self.state: EvacuationStateName | None = None
        self.lang: str | None = None
        """The language of the last visitor this robot served (its task's ``lang``)."""

    async def on_start(self) -> None:
        # evacuate is read as JSON: the robot stops on any order to leave, even one whose
        # path it cannot read (then it reports itself stuck), never drops it.
        self.subscribe(self.ep, "evacuate", self._on_evacuate)
        self.on(self.ep, EmergencyChanged, self._on_changed)
        self.on(self.ep, TaskAssigned, self._on_assigned)

    def _on_assigned(self, message: Message, assigned: TaskAssigned) -> None:
        lang = assigned.params.get("lang")
        if isinstance(lang, str):
            self.lang = lang

    def _on_evacuate(self, message: Message) -> None:
        if message.destination not in (None, self.robot):
            return
        nav = self.navigator
        riding = nav.passage.riding  # read before the cancel below ends the ride
        arrivals = nav.passage.arrived(riding[0]) if riding is not None else 0
        # Already at the floor it rode to (the news came just before the order): out there.
        landed = riding[2] if riding and nav.passage.open_at(riding[0]) == riding[2] else None
        stopped: list[float] = []

        def on_velocity(command: Message) -> None:
            if not (command.payload.get("v") or command.payload.get("w")) and not stopped:
                stopped.append(time.time())

        # A tap subscribed after the base entity's handler: it runs once the frame is sent.
        unsubscribe = self.ep.subscribe("set_velocity", on_velocity, tap=True)
        try:
            nav.halt(force=True)  # first: the base stands still
        finally:
            unsubscribe()
        nav.evacuating = True
        self.tasks.abort(CUT_OFF)
        nav.cancel_goal()  # abandons the goal and lets go of every door held
        payload: dict[str, Any] = message.payload
        cabin = riding[0] if riding is not None else None
        why = f"in elevator {cabin}'s cabin: gets out where it stops" if cabin else ""
        self._report("stopped", why=why, stopped_at=stopped[0] if stopped else None)
        words: dict[str, str] = payload.get("words") or {}
        if words:
            lang = self.lang if self.lang in words else next(iter(words))
            self.ep.publish(Say(text=words[lang], lang=lang))
        try:
            steps = _steps(payload)
            landings = {
                elevator: {floor: _steps(way) for floor, way in ways.items()}
                for elevator, ways in (payload.get("landings") or {}).items()
            }
        except (KeyError, ValueError, TypeError, AttributeError) as exc:
            self._report("stuck", why=f"bad evacuation path: {exc}")
            return
        if cabin is not None:
            mine = landings.get(cabin, {})
            nav.start_evacuation(self._leave_cabin(cabin, landed, arrivals, mine))
            return
        # The server's way starts where it last saw the robot; a landing's, where it is now.
        ways = [way for each in landings.values() for way in each.values()]
        here = [way for way in ways if way and way[0].node == nav.node]
        if here and (not steps or steps[0].node != nav.node):
            steps = here[0]
        if not steps:
            self._report("stuck", why="no way to a safe spot without an elevator")
            return
        nav.start_evacuation(self._drive(steps))

    async def _leave_cabin(
        self,
        elevator: str,
        landed: str | None,
        arrivals: int,
        landings: dict[str, list[PathStep]],
    ) -> None:
        """Riding when the alarm came: call nothing, get out at the landing where the cabin
        next stands with its door open (docs/emergency.md; ``landed``: it is there already)
        and take that landing's way."""
        nav = self.navigator
        try:
            floor = landed or await nav.passage.wait_landing(elevator, arrivals)
        except NavigationError as exc:
            self._report("stuck", why=f"in elevator {elevator}'s cabin: {exc.reason}")
            return
        except YieldRequested as exc:
            self._report("stuck", why=f"in elevator {elevator}'s cabin: asked to yield {exc.area}")
            return
        steps = landings.get(floor) or []
        if not steps:
            self._report("stuck", why=f"no way to a safe spot from elevator {elevator} at {floor}")
            return
        first = steps[0]
        if first.node != nav.node:  # the cabin took it to another floor: it is there now
            nav.relocalize(first)
            self.ep.publish(
                NodeReached(robot=self.robot, node=first.node, floor=first.floor, at=time.time())
            )
        await self._drive(steps)

    async def _drive(self, steps: list[PathStep]) -> None:
        """Follow the way; stuck (reported with why), wait and try again from where it is."""
        for attempt in range(1, ATTEMPTS + 1):
            self._report("moving")
            try:
                way = self._from_here(steps)
                await self._back_to(way[0])
                await self.navigator.follow(way)
            except NavigationError as exc:
                why = exc.reason
            except YieldRequested as exc:
                why = f"asked to yield area {exc.area}"
            else:
                self._report("safe")
                return
            self.navigator.halt()
            self._report("stuck", why=f"{why} (attempt {attempt} of {ATTEMPTS})")
            if attempt < ATTEMPTS:
                await self.navigator.clock.sleep(RETRY_S)

    async def _back_to(self, start: PathStep) -> None:
        """The way starts at the node the robot last reached, which it may have just left (the
        alarm came on its way on): it drives back onto it first. Else a robot whose safe spot
        that node is would report ``safe`` where it stopped, a few metres on, and one with a
        longer way would take the node's place on the map for where it is."""
        nav = self.navigator
        if start.node != nav.node or not nav.localized or nav.floor not in (None, start.floor):
            return
        if math.hypot(start.x - nav.x, start.y - nav.y) > nav.tolerance_m:
            await nav.drive_to(start.x, start.y, stop=True)
            nav.halt()

    def _from_here(self, steps: list[PathStep]) -> list[PathStep]:
        """The rest of the way from the node the robot last reached on it."""
        nodes = [s.node for s in steps]
        here = self.navigator.node
        return steps[nodes.index(here) :] if here in nodes else steps

    def _on_changed(self, message: Message, changed: EmergencyChanged) -> None:
        if changed.state == "normal" and self.navigator.evacuating:
            log.info("%s: the fire alarm is over: back in service", self.robot)
            self.navigator.evacuating = False
            self.state = None

    def _report(
        self, state: EvacuationStateName, *, why: str = "", stopped_at: float | None = None
    ) -> None:
        self.state = state
        log.warning("%s: evacuation %s at %s %s", self.robot, state, self.navigator.node, why)
        self.ep.publish(
            EvacuationState(state=state, node=self.navigator.node, why=why, stopped_at=stopped_at)
        )


def _steps(way: dict[str, Any]) -> list[PathStep]:
    """A way's ``steps`` (an ``evacuate`` or one of its ``landings``) as path steps."""
    return [PathStep.from_dict(step) for step in way.get("steps") or []]
