"""Can K robots deadlock on this site's lock table? A bounded search of its state space.

The Traffic Manager's locks (docs/server.md, "Deadlock rule") are the site's restricted areas,
one robot each, and an elevator's cabin (its stops, when no area holds them already). A robot
driving *through* areas asks for the whole run of back-to-back areas on its way at once and
never waits while holding one: it cannot be part of a cycle. A robot that *stops* inside an
area (its goal is a point of interest, a station, a wait point, a start node, a safe spot or an
elevator stop there) holds it; when it sets off again it asks for the next run from inside, and
waits for it while holding its own: hold and wait. A deadlock is a reachable state where such
waiting robots wait for each other in a cycle.

The model, what it keeps and what it leaves out:
- places: each lock (area or cabin) is one place; the nodes outside every lock are grouped into
  the strongly connected parts of the one-way-aware graph they form (free space: robots pass
  each other there and hold nothing);
- moves: along the site's edges, one-way ones one way; a cabin carries a robot between its
  stops; doors are not locks (the BuildingInterface keeps a door open while any robot holds it),
  so a door node is free space;
- a robot in free space may enter a run of back-to-back locks when every lock of it is free,
  drive through it and come out in free space, or stop in one of its locks that has a node
  where robots stop; a robot stopped in a lock may leave to free space, or ask for a run that
  starts next to its lock: granted if free, else it waits (and keeps waiting: the search does
  not let it change its mind, as the Traffic Manager does not);
- robots are alike: a state is the sorted list of where each is and what it waits for.

Breadth-first from the robots at the site's start nodes (K robots dealt over them in turn), up
to ``max_states`` states: then it gives up and says so. ``guidebot site check --deadlock``
reports a cycle found, with the areas and a way of reaching it.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from guidebot.site.schema import Site

__all__ = ["DeadlockResult", "find_deadlock", "lock_loc"]

FREE = "free"
REST = "rest"
WAIT = "wait"

Robot = tuple[str, str, tuple[str, ...], str]
"""(mode, place, the run of locks it waits for, where that run ends): mode free (place: a free
part), rest (place: a lock it holds) or wait (rest, and asked for a run; its end is the free
part it comes out into, or "" when it stops in the run's last lock)."""
State = tuple[Robot, ...]


@dataclass
class DeadlockResult:
    robots: int
    states: int
    """States explored."""
    seconds: float
    complete: bool
    """True: every reachable state was explored (no cycle means none is reachable)."""
    cycle: list[tuple[str, str]] = field(default_factory=list)
    """(lock held, lock waited for), robot by robot around the cycle; empty: none found."""
    trace: list[str] = field(default_factory=list)
    """How the deadlock is reached, one line per move."""
    reason: str = ""

    @property
    def deadlock(self) -> bool:
        return bool(self.cycle)

    def describe(self) -> str:
        if self.cycle:
            waits = "; ".join(f"a robot stopped in {h} waits for {w}" for h, w in self.cycle)
            return f"{self.robots} robots can deadlock: {waits}"
        if self.complete:
            return (
                f"no deadlock of {self.robots} robots: {self.states} states explored in "
                f"{self.seconds:.2f} s" + (f" ({self.reason})" if self.reason else "")
            )
        return (
            f"gave up after {self.states} states ({self.seconds:.2f} s) without finding a "
            f"deadlock of {self.robots} robots: not proven"
        )


@dataclass
class _Model:
    place_of: dict[str, str]
    locks: set[str]
    rest_locks: set[str]
    succ: dict[str, set[str]]
    """place -> the places a robot can drive into from it (one step)."""
    _runs: dict[str, list[tuple[tuple[str, ...], str | None]]] = field(default_factory=dict)

    def runs(self, start: str) -> list[tuple[tuple[str, ...], str | None]]:
        """Every run of back-to-back locks from ``start``: (locks, where it ends: a free part
        it comes out into, or None: it stops in the last lock). Computed once per lock."""
        if start in self._runs:
            return self._runs[start]
        out: list[tuple[tuple[str, ...], str | None]] = self._runs.setdefault(start, [])

        def walk(path: tuple[str, ...]) -> None:
            here = path[-1]
            if here in self.rest_locks:
                out.append((path, None))
            for nxt in sorted(self.succ[here]):
                if nxt not in self.locks:
                    out.append((path, nxt))
                elif nxt not in path:
                    walk((*path, nxt))

        walk((start,))
        return out


def _model(site: Site) -> _Model:
    lock_of: dict[str, str] = {n: f"area {a.id}" for a in site.areas for n in a.nodes}
    for lift in site.elevators:
        cabin = [stop.node for stop in lift.stops]
        held = {lock_of[n] for n in cabin if n in lock_of}
        name = next(iter(held)) if len(held) == 1 else f"elevator {lift.id}"
        for n in cabin:
            lock_of.setdefault(n, name)
    nodes = [n.id for n in site.nodes]
    out: dict[str, set[str]] = {n: set() for n in nodes}
    for e in site.edges:
        if e.a in out and e.b in out:
            out[e.a].add(e.b)
            if not e.one_way:
                out[e.b].add(e.a)
    for lift in site.elevators:  # a ride: any stop to any other
        for stop in lift.stops:
            out.setdefault(stop.node, set()).update(
                t.node for t in lift.stops if t.node != stop.node
            )
    free = [n for n in nodes if n not in lock_of]
    part = _strong_parts(free, {n: {m for m in out[n] if m not in lock_of} for n in free})
    first_of: dict[int, str] = {}
    for n in sorted(free):
        first_of.setdefault(part[n], n)
    place_of = {**lock_of, **{n: f"free space around {first_of[part[n]]}" for n in free}}
    succ: dict[str, set[str]] = {p: set() for p in set(place_of.values())}
    for a, targets in out.items():
        for b in targets:
            if place_of[a] != place_of[b]:
                succ[place_of[a]].add(place_of[b])
    rest_nodes = {
        *(p.node for p in site.pois),
        *(c.node for c in site.charging_stations),
        *(w.node for w in site.wait_points),
        *(r.start_node for r in site.robots if r.start_node),
        *(stop.node for lift in site.elevators for stop in lift.stops),
        *(site.emergency.safe_spots if site.emergency else []),
    }
    locks = set(lock_of.values())
    rest = {lock_of[n] for n in rest_nodes if n in lock_of}
    return _Model(place_of, locks, rest, succ)


def _strong_parts(nodes: list[str], out: dict[str, set[str]]) -> dict[str, int]:
    """Strongly connected parts (Tarjan, iterative): node -> part number."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    part: dict[str, int] = {}
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(out[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            node, it = work[-1]
            nxt = next(it, None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on.add(nxt)
                    work.append((nxt, iter(sorted(out[nxt]))))
                elif nxt in on:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                number = len(set(part.values()))
                while True:
                    w = stack.pop()
                    on.discard(w)
                    part[w] = number
                    if w == node:
                        break
    return part


def _held(state: State) -> dict[str, int]:
    return {r[1]: i for i, r in enumerate(state) if r[0] != FREE}


def _cycle(state: State) -> list[tuple[str, str]]:
    """A cycle of waits in ``state``: robot i waits for a lock robot j holds, ... back to i."""
    holder = _held(state)
    waits: dict[int, int] = {}
    for i, (mode, _, run, _) in enumerate(state):
        if mode == WAIT:
            blocking = [holder[lock] for lock in run if lock in holder and holder[lock] != i]
            if blocking:
                waits[i] = blocking[0]
    for start in waits:
        seen: list[int] = []
        i = start
        while i in waits and i not in seen:
            seen.append(i)
            i = waits[i]
        if i in seen:
            loop = seen[seen.index(i) :]
            return [(state[j][1], state[waits[j]][1]) for j in loop]
    return []


def _moves(model: _Model, state: State) -> Iterable[tuple[State, str]]:
    """Every state one robot's move leads to, with the move in words."""
    held = _held(state)
    for i, (mode, place, want, want_end) in enumerate(state):
        others = state[:i] + state[i + 1 :]

        def put(robot: Robot, others: State = others) -> State:
            return tuple(sorted((*others, robot)))

        def granted(run: tuple[str, ...], end: str, i: int = i) -> bool:
            return all(lock not in held or held[lock] == i for lock in run)

        def drive(run: tuple[str, ...], end: str, place: str = place) -> tuple[State, str]:
            if end:
                return put((FREE, end, (), "")), f"{place} -> {' -> '.join(run)} -> {end}"
            return put((REST, run[-1], (), "")), f"{place} -> {' -> '.join(run)} (stops)"

        if mode == WAIT:
            if granted(want, want_end):
                yield drive(want, want_end)
            continue
        for nxt in sorted(model.succ[place]):
            if nxt not in model.locks:
                yield put((FREE, nxt, (), "")), f"{place} -> {nxt}"
                continue
            for run, end in model.runs(nxt):
                if granted(run, end or ""):
                    yield drive(run, end or "")
                elif mode == REST:  # asks from inside its lock: waits holding it
                    yield (
                        put((WAIT, place, run, end or "")),
                        f"{place}: waits for {', '.join(run)}",
                    )


def lock_loc(site: Site, lock: str) -> tuple[str | int, ...]:
    """Where a lock of a cycle is in the site document (``("areas", 2)``), for file:line."""
    kind, _, name = lock.partition(" ")
    section = "areas" if kind == "area" else "elevators"
    ids = [a.id for a in site.areas] if kind == "area" else [e.id for e in site.elevators]
    return (section, ids.index(name)) if name in ids else (section,)


def find_deadlock(
    site: Site, robots: int, *, max_states: int = 200_000, shortcut: bool = True
) -> DeadlockResult:
    """Search the lock table's states of ``robots`` robots on ``site`` for a cycle of waits.

    ``shortcut``: answer at once when no lock where robots stop lies next to another lock
    (then nobody ever waits while holding a lock); False explores the states all the same."""
    if robots < 1:
        raise ValueError(f"robots must be at least 1, not {robots}")
    started = time.perf_counter()
    model = _model(site)
    if shortcut and not any(model.succ[lock] & model.locks for lock in model.rest_locks):
        return DeadlockResult(
            robots,
            0,
            time.perf_counter() - started,
            True,
            reason="no lock where robots stop lies next to another lock: no robot ever waits "
            "while holding one",
        )
    starts = [r.start_node for r in site.robots if r.start_node] or [site.nodes[0].id]
    first: list[Robot] = []
    for k in range(robots):
        place = model.place_of[starts[k % len(starts)]]
        taken = {r[1] for r in first if r[0] != FREE}
        if place in model.locks and place not in taken and place in model.rest_locks:
            first.append((REST, place, (), ""))
        elif place in model.locks:
            free = sorted(p for p in model.succ[place] if p not in model.locks)
            first.append((FREE, free[0] if free else place, (), ""))
        else:
            first.append((FREE, place, (), ""))
    initial: State = tuple(sorted(first))
    parent: dict[State, tuple[State, str] | None] = {initial: None}
    queue = deque([initial])
    while queue:
        state = queue.popleft()
        cycle = _cycle(state)
        if cycle:
            trace: list[str] = []
            at: State | None = state
            while at is not None and parent[at] is not None:
                before, text = parent[at]  # type: ignore[misc]
                trace.append(text)
                at = before
            return DeadlockResult(
                robots,
                len(parent),
                time.perf_counter() - started,
                False,
                cycle=cycle,
                trace=trace[::-1],
            )
        for nxt, text in _moves(model, state):
            if nxt not in parent:
                if len(parent) >= max_states:
                    return DeadlockResult(robots, len(parent), time.perf_counter() - started, False)
                parent[nxt] = (state, text)
                queue.append(nxt)
    return DeadlockResult(robots, len(parent), time.perf_counter() - started, True)
