"""The bounded outbound queue of one hub client, with the overflow rule of docs/protocol.md.

Rule: while the client keeps up (fewer than ``coalesce_after`` messages queued) every message is
sent. Once it falls behind, a message with a coalescing key (robot_state: the robot's name)
replaces the newest queued message with the same key in place, so a slow GUI gets the newest
state of every robot and the queue stops growing. Any other message that finds the queue full
raises ``OutboxOverflow``: the hub then disconnects that client with close code 4008 and a
reason. Nothing else is ever dropped silently.

The queue itself (merging, batching, linger) is guidebot.queues.KeyedQueue, shared with the
client library's send queue; this module only fixes the hub's defaults and overflow rule.
"""

from __future__ import annotations

from guidebot.queues import KeyedQueue, QueueOverflow

__all__ = ["Outbox", "OutboxOverflow"]

OutboxOverflow = QueueOverflow
"""The client does not read fast enough: its queue is full of messages that cannot merge."""


class Outbox(KeyedQueue[bytes]):
    """Serialised messages waiting for one client's writer task."""

    def __init__(self, maxsize: int, coalesce_after: int | None = None) -> None:
        super().__init__(
            maxsize,
            coalesce_after=maxsize // 8 if coalesce_after is None else coalesce_after,
            name="hub outbox",
        )
