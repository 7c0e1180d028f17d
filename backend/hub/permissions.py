"""Who may publish what on the hub: one table of message types per role (docs/protocol.md,
"Publish permissions").

The hub stamps ``source`` with the client's name, so nobody can speak as someone else; this
table adds *what* each role may say. Authority messages (task_assigned, area_granted, door and
elevator answers, the hub's own replies) come only from the server: its in-process modules, and
the admin and module tokens (server extensions). Control messages (subscribe, unsubscribe,
ping) and pong are open to every role.
"""

from __future__ import annotations

from backend.auth import Role

__all__ = ["ALWAYS", "PUBLISH", "SERVER_ONLY", "may_publish"]

ALWAYS = frozenset({"subscribe", "unsubscribe", "ping", "pong"})
"""Control messages and heartbeats: every role."""

SERVER_ONLY = frozenset(
    {
        # tasks and traffic: decisions of the Task and Traffic Managers
        "task_assigned",
        "task_cancel",
        "task_event",
        "robot_connected",
        "robot_disconnected",
        "robot_service",
        "path",
        "area_granted",
        "area_yield",
        "staff_alert",
        # site: a published version and how far it reached the robots
        "site_changed",
        "site_rollout",
        # building: what the BuildingInterface saw or did
        "door_opened",
        "door_closed",
        "elevator_in_position",
        "command_failed",
        "building_input_changed",
        "building_module_health",
        # the fire alarm (docs/emergency.md)
        "emergency_changed",
        "evacuate",
        # staff console: lock views, its alert book, the event log as written
        "lock_changed",
        "alert_raised",
        "alert_acked",
        "event_logged",
        # the hub's own answers
        "welcome",
        "error",
    }
)
"""Types only the server may publish: its in-process modules, and the admin and module tokens
(server extensions run out of process)."""

_ROBOT = frozenset(
    {
        "robot_state",
        "battery_low",
        "battery_panic",
        "robot_fault",
        "task_request",
        "task_started",
        "task_ended",
        "petri_net_ended",
        "tour_progress",
        "task_reaction",  # the reaction chain's robot-side stamps (docs/reaction.md)
        "petri_net_event",  # markings for the console's RoboGraph monitor
        "site_loaded",
        "get_path",
        "request_area",
        "release_area",
        "open_door",
        "release_door",
        "close_door",
        "call_elevator",
        "node_reached",  # what the fleet's safety invariants are checked on
        "evacuation_state",  # its way to a safe spot during a fire alarm
        "say",  # what it says, for consoles; nothing on the server acts on it
        "ack",  # receipt of a must-arrive message (task_assigned, area_granted, ...)
        # answers to on-board requests a server module or tool may send it
        "goal_reached",
        "navigation_failed",
        "people_faced",
        "servo_in_position",
        "speech_started",
        "speech_ended",
        "continue_answer",
        "docked",
        "charged",
    }
)

_STAFF = frozenset(
    {
        "task_request",
        "open_door",
        "close_door",
        "call_elevator",
        "set_output",
        "run_petri_net",
        "kill_petri_net",
    }
)

PUBLISH: dict[Role, frozenset[str] | None] = {
    Role.ADMIN: None,  # None: every registered type
    Role.OPERATOR: _STAFF,
    Role.MODULE: None,  # a server extension run out of process (e.g. a tour module)
    Role.ROBOT: _ROBOT,
    Role.PANEL: frozenset(),  # panels request tours over REST (rate-limited, own requests only)
    Role.GUI: frozenset(),  # displays: watch only
}
"""Role -> the message types its clients may publish (besides subscribe, unsubscribe, ping)."""


def may_publish(role: Role, type_: str) -> bool:
    allowed = PUBLISH[role]
    return allowed is None or type_ in allowed or type_ in ALWAYS
