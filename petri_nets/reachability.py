"""What a Petri-net tool tells about a net from its reachability graph: whether it is bounded
(and its bound), which transitions can never fire, which markings are dead ends.

The net is taken as a plain place/transition net: every condition (a message, a timer, a guard)
is taken as possibly true, and priorities as not choosing, so what is found dead is dead
whatever the robot answers. The graph is explored breadth first up to ``max_states`` markings;
an exploration that stops there says so (``complete`` false) and claims nothing it did not see.
Unboundedness is found the Karp-Miller way: a marking that covers one on its own path with more
tokens somewhere can be pumped for ever.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from petri_nets.model import NetDoc

__all__ = ["DEFAULT_MAX_STATES", "Analysis", "analyse"]

DEFAULT_MAX_STATES = 10_000


@dataclass
class Analysis:
    states: int
    complete: bool
    """Every reachable marking was seen (else the exploration gave up at ``max_states``)."""
    bounded: bool | None
    """False when a marking can grow for ever; True when complete and not; None: not known."""
    bound: int
    """The most tokens seen in one place."""
    unbounded_places: list[str] = field(default_factory=list)
    dead_transitions: list[str] = field(default_factory=list)
    """Transitions that fire in no explored marking (never, when ``complete``; an unbounded net
    is not explored past the markings that grow)."""
    dead_ends: int = 0
    """Markings where nothing can fire and no final place is marked."""

    def as_dict(self) -> dict[str, object]:
        return {
            "states": self.states,
            "complete": self.complete,
            "bounded": self.bounded,
            "bound": self.bound,
            "unbounded_places": self.unbounded_places,
            "dead_transitions": self.dead_transitions,
            "dead_ends": self.dead_ends,
        }


def analyse(net: NetDoc, max_states: int = DEFAULT_MAX_STATES) -> Analysis:
    """Explore the net's markings from its initial one (see the module's doc)."""
    places = [p.id for p in net.places]
    index = {p: i for i, p in enumerate(places)}
    finals = [index[p.id] for p in net.places if p.final]
    pre: dict[str, dict[int, int]] = {t.id: {} for t in net.transitions}
    post: dict[str, dict[int, int]] = {t.id: {} for t in net.transitions}
    for arc in net.arcs:
        if arc.source in index and arc.target in pre:
            pre[arc.target][index[arc.source]] = (
                pre[arc.target].get(index[arc.source], 0) + arc.weight
            )
        elif arc.source in pre and arc.target in index:
            post[arc.source][index[arc.target]] = (
                post[arc.source].get(index[arc.target], 0) + arc.weight
            )
    start = tuple(p.initial for p in net.places)
    parent: dict[tuple[int, ...], tuple[int, ...] | None] = {start: None}
    todo = deque([start])
    fired: set[str] = set()
    unbounded: set[int] = set()
    dead_ends = 0
    bound = max(start, default=0)
    complete = True
    while todo:
        marking = todo.popleft()
        enabled = [t for t in net.transitions if all(marking[i] >= w for i, w in pre[t.id].items())]
        if not enabled and not any(marking[i] for i in finals):
            dead_ends += 1
        for trans in enabled:
            fired.add(trans.id)
            after = list(marking)
            for i, w in pre[trans.id].items():
                after[i] -= w
            for i, w in post[trans.id].items():
                after[i] += w
            new = tuple(after)
            if new in parent:
                continue
            grows = _covers_an_ancestor(new, marking, parent)
            if grows:
                unbounded.update(grows)
                complete = False  # not explored past it: pumping it tells nothing more
                continue
            if len(parent) >= max_states:
                complete = False
                continue
            parent[new] = marking
            bound = max(bound, *new) if new else bound
            todo.append(new)
    bounded: bool | None = False if unbounded else (True if complete else None)
    return Analysis(
        states=len(parent),
        complete=complete,
        bounded=bounded,
        bound=bound,
        unbounded_places=[places[i] for i in sorted(unbounded)],
        dead_transitions=[t.id for t in net.transitions if t.id not in fired],
        dead_ends=dead_ends,
    )


def _covers_an_ancestor(
    new: tuple[int, ...],
    at: tuple[int, ...] | None,
    parent: dict[tuple[int, ...], tuple[int, ...] | None],
) -> set[int]:
    """The places that grow when ``new`` covers a marking on the path to it (empty: none)."""
    while at is not None:
        if all(n >= a for n, a in zip(new, at, strict=True)):
            return {i for i, (n, a) in enumerate(zip(new, at, strict=True)) if n > a}
        at = parent[at]
    return set()
