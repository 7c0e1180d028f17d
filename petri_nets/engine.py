"""One running net: marking, firing, actions, timers, sub-nets (the paper's RoboGraph semantics).

Rules (docs/petri-nets.md has the long form):
- A place's action runs each time the place receives a mark (once per mark of the arc weight).
- A mark in a timer place is *held* until its timer elapses. Immediate, timer and guard
  transitions need *ready* (not held) marks; message and net_ended transitions may take held
  marks, which cancels their timers (that is how a reply beats a time-out).
- Conflicts: transitions are ranked by priority (higher first) then document order. Enabled
  immediate transitions fire lowest rank first until none is enabled. An event (a message, a
  sub-net's end) fires at most one transition: the first in rank that is enabled and matches.
- Events arriving while the instance is busy (a reply published inline by an action) wait in a
  bounded inbox and are handled right after the current step.
- A GuideBot task net ends when no place holds a mark or every mark is in a final place;
  outcome "failed" if a marked final place says so, else "done". A plain net (another tool's
  PNML) ends when no transition is enabled: "done" in a declared final marking (or when it
  declares none), else "stuck". Ending (or kill) kills all sub-nets.
- Breakpoints (a debugger attached, docs/nets.md "Attach"): an instance pauses before firing a
  transition with a breakpoint (the event that enabled it is kept); while paused every event
  waits in the inbox. ``step`` fires it and pauses before the next firing, ``resume`` fires it
  and runs to the next breakpoint. Without breakpoints the check is one attribute test.
- Monitoring costs one list append per firing: the firings of a step are reported together,
  in order, with the new counts of the places they changed, when the step is over or before
  an action runs (so monitors hear of firings before the messages they cause).
"""

from __future__ import annotations

import enum
import heapq
import logging
import random
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from petri_nets.compiled import CompiledNet
from petri_nets.templates import TemplateError, resolve

if TYPE_CHECKING:
    from guidebot.messages import Message
    from petri_nets.clock import Clock, TimerHandle

__all__ = [
    "INBOX_LIMIT",
    "REPORT_EVERY",
    "STEP_BUDGET",
    "Breakpoints",
    "Host",
    "Instance",
    "InstanceState",
    "StateError",
]

log = logging.getLogger(__name__)
_random = random.Random()

INBOX_LIMIT = 1000
"""Events queued while an instance is busy; on overflow the oldest is dropped and logged."""
REPORT_EVERY = 1000
"""Firings in one monitoring event at most: a long step is reported in parts, so an event stays
small enough for a WebSocket frame (about 10-20 kB)."""
STEP_BUDGET = 100_000
"""Firings in one step before the engine yields to the event loop (a loop of immediate
transitions must not freeze the robot)."""


class StateError(RuntimeError):
    """An illegal life-cycle transition; says what was expected."""


class Breakpoints:
    """Where an instance pauses: before the transitions of ``at`` (indexes), or before any
    firing while ``stepping``; ``passing`` is the transition a step or resume fires anyway."""

    __slots__ = ("at", "passing", "stepping")

    def __init__(self, at: frozenset[int] = frozenset()) -> None:
        self.at = at
        self.stepping = False
        self.passing: int | None = None

    def hit(self, t: int) -> bool:
        if self.passing == t:
            self.passing = None
            return False
        return self.stepping or t in self.at


class InstanceState(enum.Enum):
    CREATED = "created"
    RUNNING = "running"
    ENDED = "ended"


_TRANSITIONS: dict[InstanceState, frozenset[InstanceState]] = {
    InstanceState.CREATED: frozenset({InstanceState.RUNNING, InstanceState.ENDED}),
    InstanceState.RUNNING: frozenset({InstanceState.ENDED}),
    InstanceState.ENDED: frozenset(),
}


class Host(Protocol):
    """What an instance needs from the dispatch that runs it."""

    clock: Clock

    def publish_action(
        self, instance: Instance, type: str, payload: dict[str, Any], destination: str | None
    ) -> None: ...

    def start_child(self, parent: Instance, net: str, params: dict[str, Any]) -> Instance: ...

    monitor: bool
    """Report firings (``event(..., "fired", ...)``); read once when an instance is created."""
    step_budget: int
    """Firings in one step before yielding to the event loop."""

    def event(
        self,
        instance: Instance,
        kind: str,
        transitions: list[str] | None,
        marking: dict[str, int],
    ) -> None: ...

    def ended(self, instance: Instance) -> None: ...


class _Timer:
    """The callback of one timer mark (a slot object: cheaper than a closure per mark)."""

    __slots__ = ("handle", "instance", "place")

    def __init__(self, instance: Instance, place: int) -> None:
        self.instance = instance
        self.place = place
        self.handle: TimerHandle | None = None

    def __call__(self) -> None:
        self.instance._post(self.instance._timer_elapsed, self)

    def cancel(self) -> None:
        if self.handle is not None:
            self.handle.cancel()


class Instance:
    """A net being run: created by the dispatch, driven by events, ended once."""

    __slots__ = (
        "_busy",
        "_heap",
        "_held",
        "_inbox",
        "_nonfinal",
        "_trail",
        "breakpoints",
        "children",
        "cursors",
        "env",
        "host",
        "id",
        "main",
        "marks",
        "net",
        "outcome",
        "parent",
        "paused_at",
        "state",
    )

    def __init__(
        self,
        host: Host,
        net: CompiledNet,
        instance_id: str,
        params: dict[str, Any],
        parent: Instance | None = None,
        main: bool = False,
    ) -> None:
        self.host = host
        self.net = net
        self.id = instance_id
        self.parent = parent
        self.main = main
        self.env: dict[str, Any] = {
            **net.params,
            **params,
            "instance_id": instance_id,
            "net": net.name,
            "parent": parent.id if parent else None,
        }
        self.marks = list(net.initial)
        self._nonfinal = sum(m for m, f in zip(net.initial, net.final, strict=True) if not f)
        self._held: dict[int, deque[_Timer]] = {}
        self._heap: list[int] = []
        self._inbox: deque[tuple[Callable[..., None], tuple[Any, ...]]] = deque()
        self._busy = False
        self._trail: list[int] | None = [] if host.monitor else None
        self.children: dict[str, Instance] = {}
        self.cursors: dict[str, int] = {}
        self.state = InstanceState.CREATED
        self.outcome: str | None = None
        self.breakpoints: Breakpoints | None = None
        self.paused_at: int | None = None
        """The transition the instance is paused before (a breakpoint), or None."""

    # ---------------------------------------------------------------- life cycle

    def _move(self, new: InstanceState) -> None:
        if new not in _TRANSITIONS[self.state]:
            raise StateError(
                f"instance {self.id}: cannot go from {self.state.value} to "
                f"{new.value} (expected one of "
                f"{sorted(s.value for s in _TRANSITIONS[self.state])})"
            )
        self.state = new

    @property
    def running(self) -> bool:
        return self.state is InstanceState.RUNNING

    def begin(self) -> None:
        """Run the actions of the initially marked places, then fire what is enabled."""
        self._move(InstanceState.RUNNING)
        self.host.event(self, "started", None, self.marking())
        self._post(self._begin)

    def _begin(self) -> None:
        net = self.net
        for t in net.sources:
            heapq.heappush(self._heap, t)
        for p in net.initial_places:
            action = net.actions[p]
            if action is not None:
                for _ in range(net.initial[p]):
                    if self.state is not InstanceState.RUNNING:
                        return
                    self._act(p)
            for t in net.downstream[p]:
                heapq.heappush(self._heap, t)

    def kill(self) -> None:
        """End now with outcome "killed" (sub-nets first)."""
        if self.state is not InstanceState.ENDED:
            self._end("killed")

    # ---------------------------------------------------------------- debugging

    def set_breakpoints(self, transitions: list[str]) -> list[str]:
        """Pause before these transitions (ids; [] clears them and resumes a paused instance).
        Returns the ids that are not transitions of the net (ignored)."""
        index = {tid: i for i, tid in enumerate(self.net.trans_ids)}
        unknown = [t for t in transitions if t not in index]
        at = frozenset(index[t] for t in transitions if t in index)
        if not at:
            self.breakpoints = None
            if self.paused_at is not None:
                self._release(stepping=False)
            return unknown
        if self.breakpoints is None:
            self.breakpoints = Breakpoints(at)
        else:
            self.breakpoints.at = at
        return unknown

    def step(self) -> bool:
        """Fire the transition paused before and pause before the next firing (False: not
        paused)."""
        return self._release(stepping=True)

    def resume(self) -> bool:
        """Fire the transition paused before and run to the next breakpoint."""
        return self._release(stepping=False)

    def _release(self, *, stepping: bool) -> bool:
        t = self.paused_at
        if t is None or self.state is not InstanceState.RUNNING:
            return False
        self.paused_at = None
        if self.breakpoints is None:
            if stepping:
                self.breakpoints = Breakpoints()
        if self.breakpoints is not None:
            self.breakpoints.stepping = stepping
            self.breakpoints.passing = t
        self._post(self._fire_paused, t)
        return True

    def _fire_paused(self, t: int) -> None:
        if self._enabled_any(t):
            self._fire(t)
        elif self.breakpoints is not None:
            self.breakpoints.passing = None
        if self.net.conditions[t].kind in ("immediate", "timer", "guard"):
            heapq.heappush(self._heap, t)  # fires again if still enabled, as in _settle

    def _end(self, outcome: str) -> None:
        self._report_firings()
        self._move(InstanceState.ENDED)
        self.outcome = outcome
        for timers in self._held.values():
            for timer in timers:
                timer.cancel()
        self._held.clear()
        self._inbox.clear()
        for child in list(self.children.values()):
            child.kill()
        self.host.event(self, "ended", None, self.marking())
        self.host.ended(self)
        if self.parent is not None:
            self.parent._post(self.parent._child_ended, self)

    # ---------------------------------------------------------------- events

    def _post(self, handler: Callable[..., None], *args: Any) -> None:
        """Handle an event now, or after the current step when busy (reentrancy) or paused."""
        if self.state is not InstanceState.RUNNING:
            return
        if self._busy or self.paused_at is not None:
            if len(self._inbox) >= INBOX_LIMIT:
                dropped = self._inbox.popleft()
                log.warning("%s: inbox full, dropped the oldest event %r", self.id, dropped[0])
            self._inbox.append((handler, args))
            return
        self._busy = True
        try:
            handler(*args)
            self._settle()
            while self._inbox and self.state is InstanceState.RUNNING and self.paused_at is None:
                handler, args = self._inbox.popleft()
                handler(*args)
                self._settle()
        except Exception:
            log.exception("net %s instance %s failed", self.net.name, self.id)
            if self.state is InstanceState.RUNNING:
                self._end("failed")
        finally:
            self._busy = False
            if self._trail:
                self._report_firings()

    def _report_firings(self) -> None:
        """One monitoring event for the firings of the step: in order, with new counts."""
        trail = self._trail
        if not trail:
            return
        self._trail = []
        net = self.net
        marks = self.marks
        changed: dict[str, int] = {}
        for t in dict.fromkeys(trail):
            for p, _ in net.inputs[t]:
                changed[net.place_ids[p]] = marks[p]
            for p, _ in net.outputs[t]:
                changed[net.place_ids[p]] = marks[p]
        ids = net.trans_ids
        self.host.event(self, "fired", [ids[t] for t in trail], changed)

    def on_message(self, message: Message) -> None:
        self._post(self._message, message)

    def _message(self, message: Message) -> None:
        net = self.net
        payload = message.payload
        for t in net.by_type.get(message.type, ()):
            if not self._enabled_any(t):
                continue
            cond = net.conditions[t]
            if all(_same(_field(payload, f), value(self.env)) for f, value in cond.matches):
                for var, field in cond.binds:
                    self.env[var] = _field(payload, field)
                self._fire(t)
                if cond.binds:
                    self._recheck_guards()
                return

    def _child_ended(self, child: Instance) -> None:
        self.children.pop(child.id, None)
        net = self.net
        for t in net.by_child.get(child.net.name, ()):
            cond = net.conditions[t]
            if (cond.outcome is None or cond.outcome == child.outcome) and self._enabled_any(t):
                self._fire(t)
                return

    def _timer_elapsed(self, timer: _Timer) -> None:
        held = self._held.get(timer.place)
        if held is not None and timer in held:
            held.remove(timer)
            if not held:
                del self._held[timer.place]
            for t in self.net.downstream[timer.place]:
                heapq.heappush(self._heap, t)

    # ---------------------------------------------------------------- firing

    def _enabled_ready(self, t: int) -> bool:
        marks = self.marks
        held_map = self._held
        for p, w in self.net.inputs[t]:
            ready = marks[p]
            if held_map:
                held = held_map.get(p)
                if held:
                    ready -= len(held)
            if ready < w:
                return False
        cond = self.net.conditions[t]
        if cond.kind == "guard":
            value = self.env.get(cond.var or "")
            if cond.test == "set":
                return value is not None
            if cond.test == "unset":
                return value is None
            return cond.value is not None and _same(value, cond.value(self.env))
        return True

    def _enabled_any(self, t: int) -> bool:
        marks = self.marks
        for p, w in self.net.inputs[t]:
            if marks[p] < w:
                return False
        return True

    def _settle(self) -> None:
        """Fire enabled immediate transitions, lowest rank first, then check for the end."""
        if self.paused_at is not None:
            return
        heap = self._heap
        budget = self.host.step_budget
        while heap and self.state is InstanceState.RUNNING:
            t = heapq.heappop(heap)
            while heap and heap[0] == t:
                heapq.heappop(heap)
            if self._enabled_ready(t):
                self._fire(t)
                if self.paused_at is not None:  # a breakpoint: t fires on step or resume
                    return
                if self._enabled_any(t):  # enough marks left to fire again
                    heapq.heappush(heap, t)
                budget -= 1
                if budget == 0:
                    self.host.clock.call_soon(lambda: self._post(_nothing))
                    return
        if self.state is not InstanceState.RUNNING:
            return
        net = self.net
        if net.plain:  # nothing is enabled: a place/transition net is over
            finals = net.final_markings
            self._end("done" if not finals or tuple(self.marks) in finals else "stuck")
        elif self._nonfinal == 0:
            failed = any(m and f for m, f in zip(self.marks, net.failed, strict=True))
            self._end("failed" if failed else "done")

    def _fire(self, t: int) -> None:
        if self.breakpoints is not None and self.breakpoints.hit(t):
            self.paused_at = t
            self._report_firings()
            self.host.event(self, "paused", [self.net.trans_ids[t]], self.marking())
            return
        net = self.net
        marks = self.marks
        final = net.final
        held_map = self._held
        nonfinal = self._nonfinal
        for p, w in net.inputs[t]:
            if held_map:
                held = held_map.get(p)
                if held:
                    extra = w - (marks[p] - len(held))
                    while extra > 0 and held:
                        held.popleft().cancel()
                        extra -= 1
                    if not held:
                        del held_map[p]
            marks[p] -= w
            if not final[p]:
                nonfinal -= w
        outputs = net.outputs[t]
        for p, w in outputs:
            marks[p] += w
            if not final[p]:
                nonfinal += w
        self._nonfinal = nonfinal
        trail = self._trail
        if trail is not None:
            trail.append(t)
            if len(trail) >= REPORT_EVERY:
                self._report_firings()
        heap = self._heap
        for p, w in outputs:
            if net.actions[p] is not None:
                for _ in range(w):
                    if self.state is not InstanceState.RUNNING:
                        return  # killed by someone reacting inline to an earlier action
                    self._act(p)
            for d in net.downstream[p]:
                heapq.heappush(heap, d)

    def _recheck_guards(self) -> None:
        for t in self.net.guards:
            heapq.heappush(self._heap, t)

    # ---------------------------------------------------------------- actions

    def _act(self, p: int) -> None:
        action = self.net.actions[p]
        assert action is not None
        if self._trail:  # monitors hear of the firings before the messages they cause
            self._report_firings()
        kind = action.kind
        if kind == "publish":
            self.host.publish_action(
                self, action.type or "", action.body(self.env), action.destination
            )
        elif kind == "timer":
            assert action.seconds is not None
            seconds = float(action.seconds(self.env))
            timer = _Timer(self, p)
            self._held.setdefault(p, deque()).append(timer)
            timer.handle = self.host.clock.call_later(seconds, timer)
        elif kind == "run":
            child = self.host.start_child(self, action.net or "", action.body(self.env))
            if action.var:
                self.env[action.var] = child.id
        elif kind == "kill":
            for child in [c for c in self.children.values() if c.net.name == action.net]:
                child.kill()
        elif kind == "next":
            values = self.env.get(action.list or "")
            if not isinstance(values, list):
                raise TemplateError(f"next: parameter {action.list!r} is not a list")
            var = action.var or ""
            if action.order == "random" and values:
                index = _random.randrange(len(values))
                self.env[var] = values[index]
                self.env[f"{var}_index"] = index
                self._recheck_guards()
                return
            index = self.cursors.get(var, 0)
            if index < len(values):
                self.env[var] = values[index]
                self.env[f"{var}_index"] = index
                self.cursors[var] = index + 1
            else:
                self.env[var] = None
            self._recheck_guards()

    # ---------------------------------------------------------------- views

    def awaited(self) -> list[dict[str, Any]]:
        """The messages the instance waits for now: each enabled message transition with its
        type and the field values it must carry (a simulation offers them as replies)."""
        net = self.net
        out = []
        for type_, transitions in net.by_type.items():
            for t in transitions:
                if not self._enabled_any(t):
                    continue
                payload: dict[str, Any] = {}
                for field, value in net.conditions[t].matches:
                    try:
                        payload[field] = value(self.env)
                    except TemplateError:
                        continue  # a variable not set yet: any value does
                out.append({"transition": net.trans_ids[t], "type": type_, "payload": payload})
        return out

    def marking(self) -> dict[str, int]:
        """Marks per place id (places with marks only)."""
        return {pid: m for pid, m in zip(self.net.place_ids, self.marks, strict=True) if m}


def _nothing() -> None:
    """An empty event: resumes a step that used up its budget."""


def _field(payload: dict[str, Any], path: str) -> Any:
    try:
        return resolve(path, payload)
    except TemplateError:
        return None


def _same(actual: Any, expected: Any) -> bool:
    """Equality that forgives a number or a boolean written as text in the net (``value="2"``,
    ``value="true"``)."""
    if isinstance(actual, bool) and isinstance(expected, str):
        return expected == ("true" if actual else "false")
    return actual == expected or (
        actual is not None
        and not isinstance(actual, str)
        and isinstance(expected, str)
        and str(actual) == expected
    )
