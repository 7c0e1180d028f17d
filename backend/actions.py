"""Who may do what: one rule per action, whichever way the action arrives (REST or the hub).

REST routes take their role check from ``RULES`` (``backend/rest/deps.py``, ``require_action``)
and the hub its publish check (``backend/hub/permissions.py``), so a role allowed an action over
one is allowed it over the other: ``kill_petri_net`` is the hub message and ``POST
/api/nets/kill`` alike, ``task_request`` the hub message and ``POST /api/tasks`` alike
(docs/security.md; tests/server/test_permissions.py reads the docs' tables against this one).
The admin may do everything.
"""

from __future__ import annotations

from backend.auth import Role, RoleCheck, require_roles
from guidebot.task_kinds import VISITOR_KINDS

__all__ = [
    "PANEL_MAX_PRIORITY",
    "REST_ONLY",
    "RULES",
    "SERVER_ROLES",
    "TASK_RATE_LIMITED",
    "allowed_roles",
    "require_action",
    "task_request_refusal",
]

SERVER_ROLES = frozenset({Role.ADMIN, Role.MODULE})
"""Trusted like server code on the hub: every registered message type, server-only ones too."""

_OPERATOR = frozenset({Role.OPERATOR})
_PEOPLE = frozenset({Role.OPERATOR, Role.INSTALLER, Role.AUTHOR, Role.VIEWER})
"""Every role an account may have but admin (backend/accounts)."""
_REQUESTERS = frozenset({Role.OPERATOR, Role.PANEL, Role.ROBOT})
_READERS = _PEOPLE | {Role.PANEL, Role.ROBOT, Role.GUI}
_ROBOT = frozenset({Role.ROBOT})
_ROBOT_OR_OPERATOR = frozenset({Role.OPERATOR, Role.ROBOT})

RULES: dict[str, frozenset[Role]] = {
    # REST-only actions (their routes: docs/server.md, "REST API and roles")
    "administer": frozenset({Role.INSTALLER}),  # the site editor: site, drafts, versions, uploads
    "manage_accounts": frozenset(),  # people's accounts (backend/accounts)
    "operate": _OPERATOR,  # the staff console's changes: tasks, robots, locks, alerts, building
    "watch": _OPERATOR | {Role.VIEWER, Role.AUTHOR},  # its reads (authors: attach targets)
    "building_modes": _OPERATOR,  # close a gallery, nodes, a door or a lift (backend/closures)
    "follow_tasks": _REQUESTERS,  # tasks one may see and cancel (own only for panels, robots)
    "read_tasks": _REQUESTERS | {Role.VIEWER},  # the same tasks, to read only
    "see_robot": _ROBOT_OR_OPERATOR,  # one robot's view (a robot: itself only)
    "plan_path": _ROBOT_OR_OPERATOR | {Role.VIEWER},  # the console's map shows a robot's path
    "read_metrics": _OPERATOR,  # GET /metrics (or the metrics token)
    "read_reports": _OPERATOR | {Role.VIEWER},  # GET /api/reports (docs/reports.md)
    "read_nets": _OPERATOR | {Role.AUTHOR, Role.VIEWER},  # the net editor's reads (docs/nets.md)
    "edit_nets": frozenset({Role.AUTHOR}),  # publish nets, restore a version (docs/nets.md)
    "manage_notifications": frozenset(),  # e-mail and webhook channels, SMTP (backend/notify)
    "read_notifications": _OPERATOR | {Role.VIEWER},  # their delivery log
    "book": _OPERATOR,  # bookings: create, move, cancel (backend/bookings)
    "read_bookings": _OPERATOR | {Role.VIEWER},  # bookings: list, one, its history
    "read": _READERS,  # tours, points of interest, the visitor menu, the map, /api/me
    # Actions that arrive over REST and the hub alike
    "task_request": _REQUESTERS | {Role.MODULE},  # POST /api/tasks
    "kill_petri_net": frozenset({Role.MODULE}),  # POST /api/nets/kill
    # Hub-only actions: message types (docs/protocol.md, "Publish permissions")
    "open_door": _ROBOT_OR_OPERATOR,
    "close_door": _ROBOT_OR_OPERATOR,
    "call_elevator": _ROBOT_OR_OPERATOR,
    "set_output": _OPERATOR,
    "run_petri_net": _OPERATOR,
    **{
        type_: _ROBOT
        for type_ in (
            "robot_state",
            "battery_low",
            "battery_panic",
            "robot_fault",
            "task_started",
            "task_ended",
            "petri_net_ended",
            "tour_progress",
            "task_reaction",  # the reaction chain's robot-side stamps (docs/reaction.md)
            "petri_net_event",  # markings for the console's RoboGraph monitor
            "robocan_status",  # CAN modules and counters for the console's robot view
            "site_loaded",
            "nets_loaded",  # which published nets it starts (docs/nets.md, "Publish")
            "get_path",
            "request_area",
            "release_area",
            "release_door",
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
        )
    },
}
"""Action -> the roles besides admin that may do it. A hub message type missing here is
server-only (admin and module tokens: ``SERVER_ROLES``)."""

REST_ONLY = frozenset(
    {
        "administer",
        "manage_accounts",
        "operate",
        "watch",
        "building_modes",
        "follow_tasks",
        "read_tasks",
        "see_robot",
        "plan_path",
        "read_metrics",
        "read_reports",
        "read_nets",
        "edit_nets",
        "manage_notifications",
        "read_notifications",
        "book",
        "read_bookings",
        "read",
    }
)
"""The actions that are not hub message types."""


def allowed_roles(action: str) -> frozenset[Role]:
    """Every role that may do ``action`` (admin included); KeyError for an unknown action."""
    return RULES[action] | {Role.ADMIN}


def require_action(action: str) -> RoleCheck:
    """FastAPI dependency: the caller's token, checked against the one rule for ``action``
    (the same rule the hub's publish check reads)."""
    return require_roles(*allowed_roles(action), action=action)


TASK_RATE_LIMITED = frozenset({Role.PANEL, Role.ROBOT})
"""Visitor-facing requesters (kiosks, robot screens) are rate-limited, over REST and the hub;
staff and server extensions are not."""

PANEL_MAX_PRIORITY = 5


def task_request_refusal(
    role: Role, name: str, *, kind: str, priority: int, robot: str | None
) -> str | None:
    """Why this caller may not request this task (None: it may): the same conditions over
    REST (``POST /api/tasks``) and the hub (``task_request``)."""
    if role in SERVER_ROLES:
        return None
    if role is Role.PANEL:
        if kind not in VISITOR_KINDS or robot is not None:
            return "panels may request tours and points of interest only"
        if priority > PANEL_MAX_PRIORITY:
            return f"panels may not ask for priority above {PANEL_MAX_PRIORITY}"
    if role is Role.ROBOT and robot not in (None, name):
        return "a robot may request tasks only for itself"
    return None
