"""Restricted-area locks: exclusive, granted in request order, with deadlock prevention and
detection (docs/server.md, "Lock policy" and "Deadlock rule").

Pure bookkeeping, no I/O: every call returns what the Traffic Manager must tell robots.

Prevention: a request may name a *chain* of areas the robot will cross back to back (no free
node between them). The chain is granted all at once or not at all, so a robot never holds one
area of a chain while waiting for the next (no hold-and-wait inside a chain).

Detection: a robot waits for the holders of the areas its request needs; those edges form the
wait-for graph. A robot waits for one request at a time, so a cycle is found by walking from
the new waiter. The cycle is broken by asking its newest waiter to yield the area it holds that
the others need: it backs off to a passing place and releases the area there (area_yield).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

__all__ = [
    "AreaLocks",
    "Cut",
    "Grant",
    "LockError",
    "LockState",
    "LockView",
    "OfflineLock",
    "Yield",
]


class LockError(ValueError):
    """A lock operation that makes no sense (unknown area, releasing a lock one does not hold)."""


class LockState(StrEnum):
    FREE = "free"
    HELD = "held"
    """Held by a connected robot."""
    HOLDER_OFFLINE = "holder_offline"
    """Its robot dropped off the network: kept (it may be inside), shown to staff."""
    YIELDING = "yielding"
    """Its robot was asked to back off (deadlock resolution) and has not released it yet."""


# The life cycle of one area lock; anything else is a bug and raises.
TRANSITIONS: dict[LockState, frozenset[LockState]] = {
    LockState.FREE: frozenset({LockState.HELD}),
    LockState.HELD: frozenset({LockState.FREE, LockState.HOLDER_OFFLINE, LockState.YIELDING}),
    LockState.HOLDER_OFFLINE: frozenset({LockState.FREE, LockState.HELD, LockState.YIELDING}),
    LockState.YIELDING: frozenset({LockState.FREE, LockState.HOLDER_OFFLINE, LockState.HELD}),
}


@dataclass(frozen=True, slots=True)
class Grant:
    robot: str
    area: str
    request_id: str | None
    again: bool = False
    """The robot held the area already (it asked again: a lost answer, a restart, a new
    leader): answered, but no new grant."""


@dataclass(frozen=True, slots=True)
class Yield:
    robot: str
    area: str
    cycle: tuple[str, ...]
    wanted: tuple[str, ...] = ()
    """The areas the yielding robot waited for (its wait is dropped while it backs off)."""


@dataclass(frozen=True, slots=True)
class Cut:
    """A waiting request that lost areas the site no longer has (``reshape``)."""

    robot: str
    areas: tuple[str, ...]
    """The areas it waited for that are gone."""
    request_id: str | None
    still_waiting: bool
    """Other areas of its chain remain, and it waits for them in its old place."""


@dataclass(frozen=True, slots=True)
class OfflineLock:
    """A lock whose holder has been offline longer than the grace period."""

    area: str
    robot: str
    offline_s: float
    released: bool
    """True: released (never seen inside); False: kept (it may be inside), staff alerted."""


@dataclass(frozen=True, slots=True)
class LockView:
    area: str
    state: LockState
    holder: str | None
    since: float | None
    entered: bool
    waiting: list[str]


@dataclass(slots=True)
class _Lock:
    area: str
    state: LockState = LockState.FREE
    holder: str | None = None
    since: float | None = None
    entered: bool = False
    offline_since: float | None = None
    """Monotonic time its holder dropped off the network (None while online)."""
    alerted: bool = False
    """Staff were told this offline holder keeps it (once per offline period)."""

    def move(self, new: LockState) -> None:
        if new not in TRANSITIONS[self.state]:
            raise LockError(
                f"area {self.area}: cannot go from {self.state.value} to {new.value} "
                f"(expected one of {sorted(s.value for s in TRANSITIONS[self.state])})"
            )
        self.state = new


@dataclass(slots=True)
class _Wait:
    robot: str
    areas: tuple[str, ...]
    request_id: str | None
    seq: int
    since: float = field(default_factory=time.monotonic)


class AreaLocks:
    """All area locks of a site. ``max_waiting`` bounds the waiting list (one entry per robot)."""

    def __init__(self, areas: list[str], *, max_waiting: int = 100_000) -> None:
        self._locks = {a: _Lock(a) for a in areas}
        self._waits: dict[str, _Wait] = {}  # robot -> its one waiting request, FIFO by seq
        self._seq = itertools.count()
        self._offline: set[str] = set()
        self._held: dict[str, list[str]] = {}  # robot -> areas it holds, in grant order
        self.max_waiting = max_waiting
        self.deadlocks_resolved = 0

    # --- queries -------------------------------------------------------------------------
    @property
    def areas(self) -> list[str]:
        return list(self._locks)

    def holder(self, area: str) -> str | None:
        return self._lock(area).holder

    def held_by(self, robot: str) -> list[str]:
        return list(self._held.get(robot, ()))

    def entered(self, area: str) -> bool:
        return self._lock(area).entered

    def waiting_for(self, robot: str) -> tuple[str, ...] | None:
        wait = self._waits.get(robot)
        return wait.areas if wait else None

    def view(self) -> list[LockView]:
        order = sorted(self._waits.values(), key=lambda w: w.seq)
        return [
            LockView(
                area=a,
                state=lock.state,
                holder=lock.holder,
                since=lock.since,
                entered=lock.entered,
                waiting=[w.robot for w in order if a in w.areas],
            )
            for a, lock in self._locks.items()
        ]

    def wait_for_graph(self) -> dict[str, set[str]]:
        """robot -> the robots holding areas it waits for."""
        graph: dict[str, set[str]] = {}
        for wait in self._waits.values():
            holders = {
                h
                for a in wait.areas
                if (h := self._locks[a].holder) is not None and h != wait.robot
            }
            graph[wait.robot] = holders
        return graph

    # --- changes -------------------------------------------------------------------------
    def request(
        self, robot: str, areas: tuple[str, ...] | list[str], request_id: str | None = None
    ) -> tuple[list[Grant], list[Yield]]:
        """Ask for ``areas`` (one area, or a chain granted all at once).

        Returns the grants now possible (possibly none: the robot waits in order) and the
        yields needed to break a deadlock the request closes.
        """
        chain = tuple(dict.fromkeys(areas))
        if not chain:
            raise LockError("no area requested")
        for a in chain:
            self._lock(a)
        if robot not in self._waits and len(self._waits) >= self.max_waiting:
            raise LockError(f"too many robots waiting ({self.max_waiting})")
        # A new request replaces the robot's previous one (it asks for one thing at a time);
        # the same request again (a re-ask, a resync) keeps its place in line (dispatch, issue
        # 36: a robot waiting for the lift is never sent to the back by asking again).
        old = self._waits.get(robot)
        seq = old.seq if old is not None and old.areas == chain else next(self._seq)
        since = old.since if old is not None and old.areas == chain else time.monotonic()
        self._waits[robot] = _Wait(robot, chain, request_id, seq, since)
        grants = self._grant_waiting()
        if robot not in self._waits:
            return grants, []
        return grants, self._resolve_cycle(robot)

    def release(self, robot: str, area: str) -> list[Grant]:
        lock = self._lock(area)
        if lock.holder != robot:
            raise LockError(f"{robot} does not hold area {area} (holder: {lock.holder})")
        self._free(lock)
        return self._grant_waiting()

    def release_all(self, robot: str, *, keep: set[str] | None = None) -> list[Grant]:
        """Release everything ``robot`` holds except ``keep``; drop its waiting request."""
        self._waits.pop(robot, None)
        for area in self.held_by(robot):
            if not (keep and area in keep):
                self._free(self._locks[area])
        return self._grant_waiting()

    def cancel_wait(self, robot: str) -> list[Grant]:
        self._waits.pop(robot, None)
        return self._grant_waiting()

    def force_release(self, area: str) -> tuple[str | None, list[Grant]]:
        """Staff release (e.g. the holder is offline and known to be outside)."""
        lock = self._lock(area)
        holder = lock.holder
        if holder is not None:
            self._free(lock)
        return holder, self._grant_waiting()

    def reshape(self, areas: list[str]) -> tuple[list[Cut], list[Grant]]:
        """The site's areas changed (a publish): new areas start free; the locks of removed
        ones go, with their holders' claims; every other lock keeps its holder, state and
        waiters in their order. A wait loses the removed areas of its chain (returned, so the
        robot is told at once rather than at its time-out) and ends when none is left.
        Returns those cuts and the grants now possible."""
        keep = dict.fromkeys(areas)
        for area in keep:
            self._locks.setdefault(area, _Lock(area))
        for area in [a for a in self._locks if a not in keep]:
            lock = self._locks.pop(area)
            held = self._held.get(lock.holder or "", [])
            if area in held:
                held.remove(area)
                if not held:
                    self._held.pop(lock.holder or "", None)
        cuts: list[Cut] = []
        for robot, wait in list(self._waits.items()):
            gone = tuple(a for a in wait.areas if a not in keep)
            if not gone:
                continue
            left = tuple(a for a in wait.areas if a in keep)
            if left:
                wait.areas = left
            else:
                del self._waits[robot]
            cuts.append(Cut(robot, gone, wait.request_id, still_waiting=bool(left)))
        return cuts, self._grant_waiting()

    def set_online(self, robot: str, online: bool, now: float | None = None) -> None:
        """Offline holders keep their locks for now (they may be inside); the state shows it
        and ``expire_offline`` decides after the grace period."""
        if online == (robot not in self._offline):
            return
        now = time.monotonic() if now is None else now
        if online:
            self._offline.discard(robot)
        else:
            self._offline.add(robot)
        for area in self._held.get(robot, ()):
            lock = self._locks[area]
            if not online and lock.state is LockState.HELD:
                lock.move(LockState.HOLDER_OFFLINE)
            elif online and lock.state is LockState.HOLDER_OFFLINE:
                lock.move(LockState.HELD)
            lock.offline_since = None if online else now
            lock.alerted = False

    def is_online(self, robot: str) -> bool:
        return robot not in self._offline

    def expire_offline(
        self, now: float, grace_s: float, may_be_inside: Callable[[str, str], bool]
    ) -> tuple[list[OfflineLock], list[Grant]]:
        """Locks whose holder has been offline for ``grace_s``: released when the holder was
        never inside (``may_be_inside(robot, area)`` false), else kept and reported once.

        Returns what was decided (for the staff alert and the log) and the grants now possible.
        """
        decided: list[OfflineLock] = []
        for lock in self._locks.values():
            since, robot = lock.offline_since, lock.holder
            if since is None or robot is None or robot not in self._offline:
                continue
            offline_s = now - since
            if offline_s < grace_s:
                continue
            if lock.entered or may_be_inside(robot, lock.area):
                if not lock.alerted:
                    lock.alerted = True
                    decided.append(OfflineLock(lock.area, robot, offline_s, released=False))
                continue
            self._free(lock)
            decided.append(OfflineLock(lock.area, robot, offline_s, released=True))
        grants = self._grant_waiting() if any(d.released for d in decided) else []
        return decided, grants

    def adopt(self, robot: str, area: str, *, entered: bool) -> bool:
        """A robot says it holds ``area`` (its resync after a server restart): a free lock is
        given to it at once, ahead of any waiter. False when another robot holds it."""
        lock = self._lock(area)
        if lock.holder == robot:
            lock.entered = lock.entered or entered
            return True
        if lock.holder is not None:
            return False
        lock.move(LockState.HELD)
        lock.holder = robot
        lock.since = time.time()
        lock.entered = entered
        self._held.setdefault(robot, []).append(area)
        wait = self._waits.get(robot)
        if wait is not None and area in wait.areas:
            del self._waits[robot]
        if robot in self._offline:
            lock.move(LockState.HOLDER_OFFLINE)
            lock.offline_since = time.monotonic()
        return True

    def mark_entered(self, robot: str, area: str) -> None:
        lock = self._lock(area)
        if lock.holder == robot:
            lock.entered = True

    # --- internals -----------------------------------------------------------------------
    def _lock(self, area: str) -> _Lock:
        try:
            return self._locks[area]
        except KeyError:
            raise LockError(f"unknown area {area!r}") from None

    def _free(self, lock: _Lock) -> None:
        lock.move(LockState.FREE)
        if lock.holder is not None:
            held = self._held.get(lock.holder, [])
            if lock.area in held:
                held.remove(lock.area)
            if not held:
                self._held.pop(lock.holder, None)
        lock.holder = None
        lock.since = None
        lock.entered = False
        lock.offline_since = None
        lock.alerted = False

    def _grant_waiting(self) -> list[Grant]:
        """Grant waiting requests in arrival order; an earlier waiter's areas are claimed, so a
        later one cannot overtake it on those areas (no starvation)."""
        grants: list[Grant] = []
        claimed: dict[str, list[_Wait]] = {}
        for wait in sorted(self._waits.values(), key=lambda w: w.seq):
            # An area the robot holds is never waited for, and a claim does not hold back the
            # robot its claimant waits on: either would make it wait on itself (issue 36).
            free = all(
                self._locks[a].holder == wait.robot
                or (
                    self._locks[a].holder is None
                    and all(self._waits_on(w, wait.robot) for w in claimed.get(a, ()))
                )
                for a in wait.areas
            )
            if not free:
                for a in wait.areas:
                    claimed.setdefault(a, []).append(wait)
                continue
            del self._waits[wait.robot]
            now = time.time()
            for a in wait.areas:
                lock = self._locks[a]
                again = lock.holder == wait.robot
                if lock.holder is None:
                    lock.move(LockState.HELD)
                    lock.holder = wait.robot
                    self._held.setdefault(wait.robot, []).append(a)
                    lock.since = now
                    if wait.robot in self._offline:
                        lock.move(LockState.HOLDER_OFFLINE)
                        lock.offline_since = time.monotonic()
                grants.append(Grant(wait.robot, a, wait.request_id, again))
        return grants

    def _waits_on(self, wait: _Wait, robot: str) -> bool:
        """``wait`` needs an area ``robot`` holds."""
        return any(self._locks[a].holder == robot for a in wait.areas)

    def _resolve_cycle(self, start: str) -> list[Yield]:
        """Walk the wait-for graph from ``start``; on a cycle, the newest waiter yields."""
        cycle = _find_cycle(start, self.wait_for_graph())
        if not cycle:
            return []
        victim = max(cycle, key=lambda r: self._waits[r].seq)
        self.deadlocks_resolved += 1
        return self.ask_to_yield(victim, cycle)

    def cycles(self) -> list[list[str]]:
        """Every cycle of the wait-for graph (each once, from its first robot in name order);
        each robot waits for the next, the last for the first."""
        graph = self.wait_for_graph()
        found: dict[frozenset[str], list[str]] = {}
        for start in sorted(graph):
            cycle = _find_cycle(start, graph)
            if cycle:
                found.setdefault(frozenset(cycle), cycle)
        return list(found.values())

    def newest_waiter(self, robots: list[str]) -> str:
        return max(robots, key=lambda r: self._waits[r].seq if r in self._waits else -1)

    def ask_to_yield(
        self,
        victim: str,
        cycle: list[str],
        *,
        again: bool = False,
        areas: tuple[str, ...] | None = None,
    ) -> list[Yield]:
        """``victim`` backs off: the areas it holds that the rest of ``cycle`` waits for (or
        ``areas``) move to YIELDING (``again``: those already yielding are asked again, the
        word may have been lost), and its own wait is dropped (it asks again once it has
        backed off)."""
        needed = (
            set(areas)
            if areas is not None
            else {
                a for r in cycle if r != victim and r in self._waits for a in self._waits[r].areas
            }
        )
        wanted = self._waits[victim].areas if victim in self._waits else ()
        yields: list[Yield] = []
        for a in sorted(needed):
            lock = self._locks[a]
            if lock.holder != victim:
                continue
            if lock.state is not LockState.YIELDING:
                lock.move(LockState.YIELDING)
            elif not again:
                continue
            yields.append(Yield(victim, a, tuple(cycle), tuple(wanted)))
        self._waits.pop(victim, None)
        return yields

    def yielding(self) -> list[tuple[str, str]]:
        """(robot, area) of every lock whose holder was asked to back off and still holds it."""
        return [
            (lock.holder, lock.area)
            for lock in self._locks.values()
            if lock.state is LockState.YIELDING and lock.holder is not None
        ]

    def waiters_on(self, area: str) -> list[str]:
        return [w.robot for w in self._waits.values() if area in w.areas]


def _find_cycle(start: str, graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle reached from ``start`` in the wait-for graph (depth first), or None."""
    path: list[str] = []
    on_path: set[str] = set()

    def dfs(robot: str) -> list[str] | None:
        path.append(robot)
        on_path.add(robot)
        for nxt in sorted(graph.get(robot, ())):
            if nxt in on_path:
                return path[path.index(nxt) :]
            if nxt in graph:
                found = dfs(nxt)
                if found:
                    return found
        on_path.discard(path.pop())
        return None

    return dfs(start)
