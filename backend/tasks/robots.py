"""What the Task Manager knows about each robot, from its robot_state and alarms."""

from __future__ import annotations

from dataclasses import dataclass

from guidebot.site.schema import RobotConfig

__all__ = ["RobotInfo"]


@dataclass(slots=True)
class RobotInfo:
    name: str
    config: RobotConfig
    online: bool = False
    last_seen: float | None = None
    offline_since: float | None = None
    node: str | None = None
    floor: str | None = None
    battery: float = 1.0
    mode: str = "offline"
    reported_task: str | None = None
    current: str | None = None
    """The task the Task Manager gave it and considers live."""
    needs_charge: bool = False
    fault: bool = False
    out_of_service: bool = False
    """Taken out of service by staff: gets no tasks but the go_to/charge staff pin to it."""
    held_up: bool = False
    """Its way is blocked (a door that did not open) or it has waited long for a door or an
    area (backend/tasks/presence.py): nobody can tell when it is free (docs/visitor.md)."""
    waiting_since: float | None = None
    """When its navigation started waiting for a door or an area (None: not waiting)."""
    refused: bool = False
    """It refused a task as busy with another: no new task until a robot_state shows it runs
    nothing or only what we gave it."""

    def as_dict(self) -> dict[str, object]:
        return {
            "name": self.name,
            "online": self.online,
            "mode": self.mode,
            "node": self.node,
            "floor": self.floor,
            "battery": self.battery,
            "task_id": self.current,
            "reported_task_id": self.reported_task,
            "needs_charge": self.needs_charge,
            "fault": self.fault,
            "out_of_service": self.out_of_service,
            "held_up": self.held_up,
            "last_seen": self.last_seen,
        }
