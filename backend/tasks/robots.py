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
    """When its last robot_state came, on the Task Manager's clock (monotonic: time-outs)."""
    seen_at: float | None = None
    """The same moment as a Unix time (``GET /api/robots`` ``last_seen``), for people."""
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
    touring_s: float = 0.0
    """Seconds it has spent on visitors' tasks since this server started (turn taking:
    backend/tasks/choice.py)."""
    drain_per_s: float | None = None
    """Battery fraction it uses per second on a task, learned from its robot_state (None: not
    yet known): a tour it cannot finish is not given to it (backend/tasks/charging.py)."""
    battery_at: tuple[float, float] | None = None
    """(when, level) of its last battery reading while not charging (to learn the drain)."""
    charge_per_s: float | None = None
    """Battery fraction a charger gives it per second, learned like the drain (None: not yet
    known): when it must start charging for a booked tour (backend/tasks/battery_forecast.py)."""
    charge_at: tuple[float, float] | None = None
    """(when, level) of its last battery reading while charging (to learn the charge rate)."""
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
            "touring_s": round(self.touring_s, 1),
            "last_seen": self.seen_at,
        }
