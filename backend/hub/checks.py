"""The ordered list of checks a client's message passes on its way in (docs/protocol.md,
"Refusals"), so that the transport (backend/hub/core.py: parse, validate, route) holds no
domain policy: each part of the server registers its own checks.

The hub reads a message in steps, and a check runs after one of them (its ``Stage``): once the
type is known (the envelope not yet read), once the envelope is valid, once the payload is its
model, once the message is routable (control messages answered, destination known). Within a
stage, checks run in the order they were registered. The first refusal wins: the sender gets
its ``error`` and the message goes no further, so a later check (a rate limit that spends) never
sees a message an earlier one refused.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from guidebot.messages import Message

    from .core import RemoteClient

__all__ = ["Check", "InboundCheck", "InboundChecks", "Plan", "Refusal", "Stage"]

Refusal = tuple[str, str]
"""(error code, reason) as the sender's ``error`` payload gives them."""

InboundCheck = Callable[["RemoteClient", str, "Message | None"], Refusal | None]
"""``check(client, type, message)``: why the message is refused, or None. ``message`` is None
at ``Stage.TYPE`` (only the type is read yet)."""


class Stage(enum.IntEnum):
    """After which step of the hub's reading a check runs."""

    TYPE = 0
    """The type is registered; the envelope is not read yet (refuse cheaply)."""
    ENVELOPE = 1
    """The envelope is valid; the payload is not checked yet."""
    PAYLOAD = 2
    """The payload is its model (``message.typed(...)`` is free); ``source`` not stamped yet."""
    ROUTED = 3
    """About to be published: not a control message, its destination exists."""


Plan = tuple[tuple[InboundCheck, ...], ...]
"""The checks of one message type, per stage (indexed by ``Stage``), in order."""


@dataclass(frozen=True, slots=True)
class Check:
    name: str
    stage: Stage
    check: InboundCheck
    types: frozenset[str] | None
    """The message types it applies to; None: every type."""


class InboundChecks:
    """The registered checks; the hub asks for the plan of a type, worked out once per type."""

    def __init__(self) -> None:
        self._checks: list[Check] = []
        self.plans: dict[str, Plan] = {}
        """``plan(type)`` worked out, by type (read it first: the hub does, per message)."""

    def add(
        self,
        name: str,
        stage: Stage,
        check: InboundCheck,
        *,
        types: Iterable[str] | None = None,
    ) -> Callable[[], None]:
        """Register ``check`` after those of its stage; returns the function that removes it."""
        if any(c.name == name for c in self._checks):
            raise ValueError(f"an inbound check named {name!r} is already registered")
        entry = Check(name, stage, check, None if types is None else frozenset(types))
        self._checks.append(entry)
        self.plans.clear()

        def remove() -> None:
            if entry in self._checks:
                self._checks.remove(entry)
                self.plans.clear()

        return remove

    def plan(self, type_: str) -> Plan:
        """The checks a message of ``type_`` passes, per stage, in order."""
        plan = self.plans.get(type_)
        if plan is None:
            plan = self.plans[type_] = tuple(
                tuple(c.check for c in self._for(type_) if c.stage is stage) for stage in Stage
            )
        return plan

    def order(self, type_: str) -> list[str]:
        """The names of the checks a message of ``type_`` passes, in the order they run."""
        return [c.name for stage in Stage for c in self._for(type_) if c.stage is stage]

    def _for(self, type_: str) -> list[Check]:
        return [c for c in self._checks if c.types is None or type_ in c.types]
