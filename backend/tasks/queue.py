"""The queue of waiting tasks: higher priority first, first come first served within one."""

from __future__ import annotations

import bisect
import heapq
import itertools
from collections.abc import Iterator

from backend.tasks.model import Task, TaskState

__all__ = ["TaskQueue"]


class TaskQueue:
    """A heap with lazy deletion: re-prioritising pushes a new entry, the old one goes stale.

    Bounded by ``maxsize`` waiting tasks; a request beyond it is refused (the caller gets a
    clear error, nothing already queued is dropped).
    """

    def __init__(self, maxsize: int = 100_000) -> None:
        self.maxsize = maxsize
        self._heap: list[tuple[int, int, int, int, Task]] = []
        self._tie = itertools.count()
        self._live: dict[str, Task] = {}
        self._key: dict[str, tuple[int, int]] = {}  # task id -> (priority, seq) as indexed
        self._by_priority: dict[int, list[int]] = {}  # priority -> sorted seqs

    def __len__(self) -> int:
        return len(self._live)

    def __contains__(self, task_id: object) -> bool:
        return task_id in self._live

    @property
    def full(self) -> bool:
        return len(self._live) >= self.maxsize

    def push(self, task: Task) -> None:
        self._unindex(task.id)
        self._live[task.id] = task
        self._key[task.id] = (task.priority, task.seq)
        bisect.insort(self._by_priority.setdefault(task.priority, []), task.seq)
        heapq.heappush(self._heap, (-task.priority, task.seq, task.version, next(self._tie), task))
        if len(self._heap) > 2 * len(self._live) + 64:
            self._compact()

    def remove(self, task_id: str) -> None:
        self._live.pop(task_id, None)
        self._unindex(task_id)

    def _unindex(self, task_id: str) -> None:
        key = self._key.pop(task_id, None)
        if key is None:
            return
        seqs = self._by_priority[key[0]]
        del seqs[bisect.bisect_left(seqs, key[1])]
        if not seqs:
            del self._by_priority[key[0]]

    def _valid(self, entry: tuple[int, int, int, int, Task]) -> bool:
        prio, _, version, _, task = entry
        return (
            self._live.get(task.id) is task
            and task.version == version
            and -prio == task.priority
            and task.state is TaskState.QUEUED
        )

    def _compact(self) -> None:
        self._heap = [e for e in self._heap if self._valid(e)]
        heapq.heapify(self._heap)

    def ordered(self) -> Iterator[Task]:
        """Waiting tasks in service order (a snapshot, safe to mutate the queue meanwhile)."""
        self._compact()
        return iter([e[4] for e in sorted(self._heap)])

    def head(self) -> Iterator[Task]:
        """Waiting tasks in order, lazily: cheap when the caller stops after a few."""
        heap = self._heap
        while heap and not self._valid(heap[0]):
            heapq.heappop(heap)
        if not heap:
            return
        # Walk a copy-on-demand frontier so the heap itself is untouched.
        frontier = [(heap[0], 0)]
        while frontier:
            entry, index = heapq.heappop(frontier)
            if self._valid(entry):
                yield entry[4]
            for child in (2 * index + 1, 2 * index + 2):
                if child < len(heap):
                    heapq.heappush(frontier, (heap[child], child))

    def position(self, task: Task) -> int | None:
        """1-based place in the queue (how many are served before it, plus one)."""
        if self._live.get(task.id) is not task:
            return None
        priority, seq = self._key[task.id]
        ahead = sum(len(seqs) for p, seqs in self._by_priority.items() if p > priority)
        return 1 + ahead + bisect.bisect_left(self._by_priority[priority], seq)
