"""What raises and resolves the staff alerts (backend.alerts): the server's messages, watched.

Each cause is raised when it appears and resolved when a message says it is gone
(docs/console.md, "Alerts"):

- robot_lost: robot_disconnected, unless the robot said it is leaving (robot_state mode
  "offline" first); resolved by robot_connected or a robot_state.
- can_module_lost: robot_state.modules[name] "lost"; resolved when it no longer is.
- battery_panic: battery_panic; resolved when robot_state.battery is above its level again.
- robot_fault: robot_fault; resolved by a robot_state out of that fault (navigation, mode).
- building_command_failed: command_failed, not one a rule refused (``refused``: the fire
  alarm's zone); resolved by the device doing it (door_opened, door_closed,
  elevator_in_position, building_input_changed of the output).
- module_offline: building_module_health online false; resolved by online true.
- lock_holder_offline: lock_changed holder_offline; resolved by any other lock state.
- task_failed: task_event failed; an event: resolved when acknowledged.
- fire_alarm: emergency_changed alarm (the zones, who declared it); resolved by the state
  normal (service resumed). Seen on start too (an alarm kept across a restart).
- evacuation_stuck: evacuation_state stuck (where and why); resolved when the robot moves
  again, is safe, or the alarm is over.

The Traffic Manager raises its own (area_conflict, lock_holder_offline after the grace,
lock_released_offline) in the same store.
"""

from __future__ import annotations

from typing import Any

from backend.alerts import AlertStore
from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.building import (
    BuildingModuleHealth,
    CommandFailed,
    DoorClosed,
    DoorOpened,
)
from guidebot.payloads.console import LockChanged
from guidebot.payloads.emergency import EvacuationState
from guidebot.payloads.robot import BatteryAlarm, RobotFault, RobotMode, RobotState
from guidebot.payloads.tasks import RobotLink, TaskEvent
from guidebot.service import Service

__all__ = ["AlertWatcher"]

BATTERY_HYSTERESIS = 0.05
"""A panic alert resolves once the battery is this much above the level it panicked at."""
FAULT_NAVIGATION = {"door_blocked": "door_blocked", "bumper": "bumped"}
"""robot_fault kinds that last while the robot's navigation state says so; any other kind
lasts while its mode (or navigation) is "fault"."""


class AlertWatcher(Service):
    """Raises and resolves alerts from hub messages (tapped: commands' answers too)."""

    def __init__(self, endpoint: Endpoint, alerts: AlertStore) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.alerts = alerts
        self._leaving: set[str] = set()
        """Robots that said they are leaving (robot_state mode offline): no robot_lost."""
        self._panic: dict[str, float] = {}

    async def on_start(self) -> None:
        ep = self.endpoint
        self.on(ep, RobotState, self._on_robot_state, tap=True)
        self.on(ep, RobotLink, self._on_robot_connected, types=["robot_connected"], tap=True)
        self.on(ep, RobotLink, self._on_robot_disconnected, types=["robot_disconnected"], tap=True)
        self.on(ep, BatteryAlarm, self._on_battery_panic, types=["battery_panic"], tap=True)
        self.on(ep, RobotFault, self._on_robot_fault, tap=True)
        self.on(ep, CommandFailed, self._on_command_failed, tap=True)
        self.on(ep, DoorOpened, self._on_door, tap=True)
        self.on(ep, DoorClosed, self._on_door, tap=True)
        self.on(ep, BuildingModuleHealth, self._on_module_health, tap=True)
        self.on(ep, TaskEvent, self._on_task_event, tap=True)
        self.on(ep, LockChanged, self._on_lock_changed, tap=True)
        self.on(ep, EvacuationState, self._on_evacuation, tap=True)
        # Read as JSON: a missing door_open is not "open" here (the model's default is),
        # the emergency state is the dict emergency_now() gets too, and a button's input
        # needs only its module and point.
        self.subscribe(ep, "elevator_in_position", self._on_elevator, tap=True)
        self.subscribe(ep, "building_input_changed", self._on_input, tap=True)
        self.subscribe(ep, "emergency_changed", self._on_emergency, tap=True)

    @staticmethod
    def _robot(message: Message, robot: str) -> str:
        return robot or message.source

    # --- robots -------------------------------------------------------------------------
    def _on_robot_state(self, message: Message, state: RobotState) -> None:
        robot = self._robot(message, state.robot)
        if state.mode == RobotMode.OFFLINE:
            self._leaving.add(robot)  # its last word before a clean exit
            return
        self._leaving.discard(robot)
        self.alerts.resolve("robot_lost", robot, f"robot {robot} is back online")
        for name, module in state.modules.items():
            subject = f"{robot}/{name}"
            if module == "lost":
                if not self.alerts.is_active("can_module_lost", subject):
                    self.alerts.raise_(
                        "can_module_lost", subject, f"{robot}: CAN module {name} lost"
                    )
            else:
                self.alerts.resolve("can_module_lost", subject, f"{robot}: CAN module {name} ok")
        # A state that leaves battery out says nothing of it (the model's default is full).
        battery = state.battery if "battery" in message.payload else None
        panic = self._panic.get(robot)
        if panic is not None and battery is not None:
            if battery >= panic + BATTERY_HYSTERESIS:
                del self._panic[robot]
                self.alerts.resolve(
                    "battery_panic", robot, f"{robot}: battery back at {battery:.0%}"
                )
        navigation, mode = state.navigation, state.mode

        def over(subject: str) -> bool:
            if not subject.startswith(f"{robot}/"):
                return False
            state = FAULT_NAVIGATION.get(subject[len(robot) + 1 :])
            if state is not None:
                return navigation != state
            return mode != RobotMode.FAULT and navigation != "fault"

        self.alerts.resolve_where("robot_fault", over, f"robot {robot} is no longer in fault")

    def _on_robot_connected(self, message: Message, link: RobotLink) -> None:
        robot = self._robot(message, link.robot)
        self._leaving.discard(robot)
        self.alerts.resolve("robot_lost", robot, f"robot {robot} is back online")

    def _on_robot_disconnected(self, message: Message, link: RobotLink) -> None:
        robot = self._robot(message, link.robot)
        if robot in self._leaving:
            self._leaving.discard(robot)
            return  # it said goodbye: a clean exit is not an alert
        self.alerts.raise_("robot_lost", robot, f"robot {robot} lost its connection")

    def _on_battery_panic(self, message: Message, alarm: BatteryAlarm) -> None:
        robot = self._robot(message, alarm.robot)
        level = float(alarm.level)
        self._panic[robot] = level
        self.alerts.raise_("battery_panic", robot, f"{robot}: battery at {level:.0%}")

    def _on_robot_fault(self, message: Message, fault: RobotFault) -> None:
        robot = self._robot(message, fault.robot)
        kind, detail = fault.kind, fault.detail
        self.alerts.raise_("robot_fault", f"{robot}/{kind}", f"{robot}: {kind} {detail}".strip())

    # --- building -----------------------------------------------------------------------
    def _on_command_failed(self, message: Message, failed: CommandFailed) -> None:
        if failed.refused:  # a rule (the fire alarm), not a device: the alarm's alert says it
            return
        command, reason = failed.command, failed.reason
        target = failed.target or reason[:40]
        self.alerts.raise_(
            "building_command_failed", f"{command}:{target}", f"{command} failed: {reason}"
        )

    def _on_door(self, message: Message, answer: DoorOpened | DoorClosed) -> None:
        door = answer.door
        if isinstance(answer, DoorOpened):
            self.alerts.resolve("building_command_failed", f"open_door:{door}", f"{door} open")
        elif answer.sensed:
            self.alerts.resolve("building_command_failed", f"close_door:{door}", f"{door} closed")

    def _on_elevator(self, message: Message) -> None:
        p = message.payload
        if p.get("door_open"):
            elevator = str(p.get("elevator"))
            self.alerts.resolve(
                "building_command_failed",
                f"call_elevator:{elevator}",
                f"elevator {elevator} arrived at floor {p.get('floor')}",
            )

    def _on_input(self, message: Message) -> None:
        point = f"{message.payload.get('module')}/{message.payload.get('point')}"
        self.alerts.resolve("building_command_failed", f"set_output:{point}", f"{point} written")

    def _on_module_health(self, message: Message, health: BuildingModuleHealth) -> None:
        module = health.module
        if not health.online:
            if not self.alerts.is_active("module_offline", module):
                error = health.last_error or "no answer"
                self.alerts.raise_("module_offline", module, f"Modbus module {module}: {error}")
        else:
            self.alerts.resolve("module_offline", module, f"Modbus module {module} is online")

    # --- tasks and locks ----------------------------------------------------------------
    def _on_task_event(self, message: Message, event: TaskEvent) -> None:
        if event.state == "failed":
            task = event.task_id
            robot = event.robot or "no robot"
            reason = event.reason
            text = f"task {task} failed ({robot})" + (f": {reason}" if reason else "")
            self.alerts.raise_("task_failed", task, text, "warning", lasting=False)

    def _on_lock_changed(self, message: Message, lock: LockChanged) -> None:
        area = lock.area
        if lock.state == "holder_offline":
            if not self.alerts.is_active("lock_holder_offline", area):
                self.alerts.raise_(
                    "lock_holder_offline",
                    area,
                    f"area {area} is held by {lock.holder}, which is offline: "
                    "release it by hand once the robot is out of the area",
                )
        else:
            why = f"area {area} is {lock.state}" + (f" ({lock.holder})" if lock.holder else "")
            self.alerts.resolve("lock_holder_offline", area, why)

    # --- the fire alarm (docs/emergency.md) ----------------------------------------------
    def emergency_now(self, state: dict[str, Any]) -> None:
        """The emergency state when the watcher starts (an alarm kept across a restart is
        published before the watcher listens)."""
        self._emergency(state)

    def _on_emergency(self, message: Message) -> None:
        self._emergency(message.payload)

    def _emergency(self, p: dict[str, Any]) -> None:
        state = p.get("state")
        if state == "normal":
            self.alerts.resolve("fire_alarm", "site", "service resumed after the fire alarm")
            self.alerts.resolve_where("evacuation_stuck", lambda _: True, "the fire alarm is over")
            return
        if state != "alarm":
            return  # input_clear: the alarm still holds until a person resumes service
        zones = "; ".join(_zone_text(z) for z in p.get("zones") or [{}])
        by = str(p.get("declared_by") or "unknown")
        who = f"alarm input {by[6:]}" if by.startswith("input:") else by
        text = f"Fire alarm: {zones} (declared by {who}): robots go to their safe spots"
        alert = self.alerts.get("fire_alarm", "site")
        if alert is None or not alert.active or alert.message != text:
            self.alerts.raise_("fire_alarm", "site", text)

    def _on_evacuation(self, message: Message, report: EvacuationState) -> None:
        robot = message.source
        if report.state == "stuck":
            where = report.node or "an unknown place"
            why = report.why or "no reason given"
            self.alerts.raise_(
                "evacuation_stuck",
                robot,
                f"{robot} is stuck on its way to safety at {where}: {why}",
            )
        else:
            self.alerts.resolve("evacuation_stuck", robot, f"{robot}: evacuation {report.state}")


def _zone_text(zone: dict[str, Any]) -> str:
    if zone.get("floors"):
        return "floor " + ", ".join(zone["floors"])
    if zone.get("areas"):
        return "area " + ", ".join(zone["areas"])
    return "the whole site"
