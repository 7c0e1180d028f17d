"""Battery alarms (docs/server.md, "Battery"): ``battery_low`` lets the current visitor task
finish, then the robot charges; ``battery_panic`` takes the task away now (back to the queue,
for another robot first). An internal task (going home) just stops, a charge task never."""

from __future__ import annotations

from backend.tasks.desk import Desk
from backend.tasks.model import Task, TaskState
from backend.tasks.robots import RobotInfo
from guidebot.messages import Message
from guidebot.payloads.robot import BatteryAlarm

__all__ = ["BatteryAlarms"]


class BatteryAlarms:
    """The Task Manager's handlers of battery_low and battery_panic."""

    def __init__(self, manager: Desk) -> None:
        self.tm = manager

    def on_battery_low(self, msg: Message, alarm: BatteryAlarm) -> None:
        robot = self.tm.robot_of(msg, alarm.robot)
        if robot is None:
            return
        robot.needs_charge = True
        current = self.tm.book.current_of(robot)
        if current is not None and current.internal and current.kind != "charge":
            self._stop(robot, current, "battery low")
        self.tm.dispatch()

    def on_battery_panic(self, msg: Message, alarm: BatteryAlarm) -> None:
        robot = self.tm.robot_of(msg, alarm.robot)
        if robot is None:
            return
        robot.needs_charge = True
        current = self.tm.book.current_of(robot)
        if current is not None and current.kind != "charge":
            if current.internal:
                self._stop(robot, current, "battery panic")
            else:
                self.tm.book.rather_not(current.id, robot.name)
                self.tm.requeue(current, "battery panic")
        self.tm.dispatch()

    def _stop(self, robot: RobotInfo, task: Task, reason: str) -> None:
        """An internal task ends here: cancelled on the robot and in the queue's books."""
        self.tm.send_cancel(robot.name, task.id, reason)
        task.move(TaskState.CANCELLED, reason=reason)
        self.tm.book.withdraw(task)
        self.tm.changed(task, "cancelled")
