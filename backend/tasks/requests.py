"""``task_request`` over the hub (robot screens, buttons, modules): a repeat is not a new task,
a refusal is an ``error``, and the answer (``task_event`` and the ack) leaves once the task is
in the database (docs/protocol.md, "Must-arrive messages")."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import OrderedDict
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from pydantic import ValidationError

from backend.tasks.model import Task, TaskError
from backend.tasks.robots import RobotInfo
from guidebot.bus import BusEndpoint
from guidebot.delivery import ack_for
from guidebot.messages import Message
from guidebot.payloads.hub import Error
from guidebot.payloads.tasks import TaskEvent, TaskRequest

if TYPE_CHECKING:
    from backend.tasks.manager import TaskStore

__all__ = ["MAX_REMEMBERED_REQUESTS", "HubRequests"]

log = logging.getLogger(__name__)

MAX_REMEMBERED_REQUESTS = 4096


class RequestDesk(Protocol):
    """What the ``task_request`` handler needs of the manager: it writes no state itself."""

    endpoint: BusEndpoint
    store: TaskStore | None

    @property
    def tasks(self) -> Mapping[str, Task]: ...
    @property
    def robots(self) -> Mapping[str, RobotInfo]: ...
    def event(self, task: Task) -> TaskEvent: ...
    def request(
        self, kind: str, params: dict[str, Any], *, priority: int, requester: str, robot: str | None
    ) -> Task: ...


class HubRequests:
    """The Task Manager's ``task_request`` handler and the answers still waiting for a write."""

    def __init__(self, manager: RequestDesk) -> None:
        self.tm = manager
        self._requests: OrderedDict[tuple[str, str], str] = OrderedDict()
        """(requester, message id) of hub task_requests -> their task: a repeat is not new."""
        self._writes: set[asyncio.Task[None]] = set()

    def on_task_request(self, msg: Message) -> None:
        tm = self.tm
        # A repeat (the robot's link sends it again until answered): the same task, answered
        # again, never a second one.
        key = (msg.source, msg.id)
        known = tm.tasks.get(self._requests.get(key, ""))
        if known is not None:
            self._answer_when_written(msg, tm.event(known))
            return
        try:
            req = msg.typed(TaskRequest)  # validated once, at the hub (docs/messages.md)
            robot = msg.source if msg.source in tm.robots else None
            # A robot requests as itself; in-process modules (buttons, RGM) may name a requester.
            requester = msg.source if robot is not None else (req.requester or msg.source)
            # A visitor at a robot's screen: that robot takes it.
            task = tm.request(
                req.kind, req.params, priority=req.priority, requester=requester, robot=robot
            )
        except (ValidationError, TaskError) as exc:
            reason = str(exc) if isinstance(exc, TaskError) else exc.errors()[0]["msg"]
            tm.endpoint.reply(msg, Error(code="task_refused", reason=reason, message_id=msg.id))
            tm.endpoint.send(ack_for(msg, tm.endpoint.name))  # a copy would be refused too
            return
        self._requests[key] = task.id
        if len(self._requests) > MAX_REMEMBERED_REQUESTS:
            self._requests.popitem(last=False)
        self._answer_when_written(msg, tm.event(task))

    def _answer_when_written(self, msg: Message, event: TaskEvent) -> None:
        """The task_event answer and the ack leave once the task is in the database (as REST
        answers with a broker): an acknowledged request survives a crash right after. Without
        a store that can flush (unit tests) or an event loop, at once."""
        flush = getattr(self.tm.store, "flush", None)
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            loop = None
        if flush is None or loop is None:
            self._answer(msg, event)
            return
        writing = loop.create_task(self._reply_after(flush, msg, event), name="task-written")
        self._writes.add(writing)
        writing.add_done_callback(self._writes.discard)

    async def _reply_after(self, flush: Callable[[], Any], msg: Message, event: TaskEvent) -> None:
        try:
            await flush()
        except Exception as exc:  # the store keeps it and writes it when the database is back
            log.warning("task %s answered before it was written: %r", event.task_id, exc)
        self._answer(msg, event)

    def _answer(self, msg: Message, event: TaskEvent) -> None:
        """task_event to the requester, and the acknowledgement that ends its link's retries."""
        self.tm.endpoint.reply(msg, event)
        self.tm.endpoint.send(ack_for(msg, self.tm.endpoint.name))

    async def finish_writes(self) -> None:
        """Stop: answers waiting for their write get 5 s to reach the database."""
        if self._writes:
            with contextlib.suppress(TimeoutError):  # a database that never answers
                async with asyncio.timeout(5.0):
                    await asyncio.gather(*self._writes, return_exceptions=True)
            for writing in self._writes:
                writing.cancel()
