"""Who may publish what on the hub (docs/protocol.md, "Publish permissions"), read from the one
table of actions the REST routes read too (``backend/actions.py``).

The hub stamps ``source`` with the client's name, so nobody can speak as someone else; the table
adds *what* each role may say. Authority messages (task_assigned, area_granted, door and
elevator answers, the hub's own replies) come only from the server: its in-process modules, and
the admin and module tokens (server extensions). Control messages (subscribe, unsubscribe,
ping) and pong are open to every role.

The hub installs these rules as its first inbound checks (backend/hub/checks.py, ``install``):
the type by role, then the envelope's ``source``, then the payload.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from backend.actions import RULES, SERVER_ROLES, task_request_refusal
from backend.auth import Role

from .checks import InboundChecks, Refusal, Stage

if TYPE_CHECKING:
    from guidebot.messages import Message

    from .core import RemoteClient

__all__ = ["ALWAYS", "install", "may_publish", "publish_refusal"]

ALWAYS = frozenset({"subscribe", "unsubscribe", "ping", "pong"})
"""Control messages and heartbeats: every role."""


def may_publish(role: Role, type_: str) -> bool:
    """Whether a client of ``role`` may publish messages of ``type_`` (a registered type)."""
    return role in SERVER_ROLES or type_ in ALWAYS or role in RULES.get(type_, frozenset())


def publish_refusal(role: Role, name: str, type_: str, payload: dict[str, Any]) -> Refusal | None:
    """Why a message this client may publish by its type is refused all the same, as (error
    code, reason); None when it is not. A robot speaking for another robot and a task requested
    in another's name are ``impersonation``; a task request the role may not make (a panel's
    charge, its priority above 5) is ``forbidden_request``, as REST answers it 403."""
    if role in SERVER_ROLES:
        return None
    if role is Role.ROBOT:
        robot = payload.get("robot")
        if robot is not None and robot != name:
            return "impersonation", f"robot {name!r} may not publish for robot {robot!r}"
    if type_ == "task_request":
        requester = payload.get("requester", "")
        if requester not in ("", name):
            return "impersonation", f"you are {name!r}; you may not request tasks as {requester!r}"
        kind, priority = payload.get("kind"), payload.get("priority", 5)
        if isinstance(kind, str) and isinstance(priority, int):
            reason = task_request_refusal(role, name, kind=kind, priority=priority, robot=None)
            if reason is not None:
                return "forbidden_request", reason
    return None


def install(checks: InboundChecks) -> None:
    """The hub's own inbound checks, in the order a client sees their refusals (docs/protocol.md,
    "Refusals"): ``forbidden_type`` before the envelope is read, ``impersonation`` of the
    envelope's source, then what the payload may say (``impersonation``,
    ``forbidden_request``)."""
    checks.add("forbidden_type", Stage.TYPE, _type_allowed)
    checks.add("source_is_sender", Stage.ENVELOPE, _speaks_as_itself)
    checks.add("payload_allowed", Stage.PAYLOAD, _payload_allowed)


def _type_allowed(client: RemoteClient, type_: str, message: Message | None) -> Refusal | None:
    role = client.role  # may_publish, inline: this runs for every message a client sends
    if role in SERVER_ROLES or type_ in ALWAYS or role in RULES.get(type_, _NOBODY):
        return None
    return (
        "forbidden_type",
        f"a {client.role.value} may not publish {type_!r} (docs/protocol.md, "
        "'Publish permissions')",
    )


def _speaks_as_itself(client: RemoteClient, type_: str, message: Message | None) -> Refusal | None:
    source = "" if message is None else message.source
    if source and source != client.name:
        return "impersonation", f"you are {client.name!r}; you may not publish as {source!r}"
    return None


def _payload_allowed(client: RemoteClient, type_: str, message: Message | None) -> Refusal | None:
    if message is None or client.role in SERVER_ROLES:
        return None
    return publish_refusal(client.role, client.name, type_, message.payload)


_NOBODY: frozenset[Role] = frozenset()
