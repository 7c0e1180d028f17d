"""The hub's side of acknowledged delivery (guidebot/delivery.py, docs/protocol.md "Delivery
guarantee"): a must-arrive message from a WebSocket client (a robot's task report, area, door or
elevator request) is acknowledged once the server's deciding modules have handled it, and a
repeat of an id already handled is acknowledged again but not published twice. A task_request
is acknowledged by the Task Manager instead, once the task is written.

With several processes (docs/scaling.md) only the leader acknowledges, for robots on every
process: a follower that acknowledged would end the robot's retries of a message that may reach
no deciding module (none runs during a fail-over). A follower passes every copy on to the
leader and shows its own clients the first.
"""

from __future__ import annotations

from guidebot.delivery import ANSWERED, MUST_ARRIVE_UP, Seen, ack_for
from guidebot.messages import Message

__all__ = ["InboundAcks"]


class InboundAcks:
    """Remembers the last ``size`` must-arrive ids per hub (keyed by sender name and id, so
    a robot that reconnects, even on a new connection, is still de-duplicated)."""

    def __init__(self, size: int = 8192, source: str = "hub") -> None:
        self.seen = Seen(size)
        self.passed = Seen(size)
        """Ids passed on while this process did not decide (its own clients see one copy);
        apart from ``seen``, so a process that comes to lead handles a copy sent again."""
        self.charged = Seen(size)
        """task_requests already charged to their sender's rate limit: a copy sent again
        (until answered) is not charged twice."""
        self.source = source
        self.acks = 0

    @staticmethod
    def wanted(message: Message) -> bool:
        return message.type in MUST_ARRIVE_UP and message.type not in ANSWERED

    def first(self, sender: str, message: Message) -> bool:
        """True if this id from ``sender`` was not handled yet (publish it), else a repeat."""
        return self.seen.first((sender, message.id))

    def first_passed(self, sender: str, message: Message) -> bool:
        """True if this id from ``sender`` was not passed on yet while not deciding."""
        return self.passed.first((sender, message.id))

    def is_repeat_request(self, sender: str, message: Message) -> bool:
        return (sender, message.id) in self.charged

    def charge(self, sender: str, message: Message) -> None:
        self.charged.first((sender, message.id))

    def ack(self, message: Message) -> Message:
        self.acks += 1
        return ack_for(message, self.source)

    @property
    def duplicates(self) -> int:
        return self.seen.duplicates
