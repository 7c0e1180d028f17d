"""The hub's rate limit on task_request (docs/security.md), registered with the hub's inbound
checks (backend/hub/checks.py) by the part of the server task requests belong to, with the
limiter REST task creation spends too (backend/api/tasks.py)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from backend.actions import TASK_RATE_LIMITED
from backend.hub.checks import InboundChecks, Refusal, Stage
from backend.ratelimit import RateLimited, RateLimiter

if TYPE_CHECKING:
    from backend.hub.core import RemoteClient
    from guidebot.messages import Message

__all__ = ["limit_task_requests"]


def limit_task_requests(checks: InboundChecks, limits: RateLimiter) -> Callable[[], None]:
    """A panel's or robot's task_request over its rate is refused ``rate_limited``, last of the
    checks (a refused one is not charged); a copy sent again until answered is charged once."""

    def within_rate(client: RemoteClient, type_: str, message: Message | None) -> Refusal | None:
        if message is None or client.role not in TASK_RATE_LIMITED:
            return None
        acks = client.hub.acks
        if acks.is_repeat_request(client.name, message):
            return None
        try:
            limits.spend(client.name, "too many task requests")
        except RateLimited as exc:
            return "rate_limited", str(exc)
        acks.charge(client.name, message)  # its copies sent again are not charged
        return None

    return checks.add("task_request_rate", Stage.ROUTED, within_rate, types=["task_request"])
