"""A validated net turned into index tables, so starting and firing never touch XML or dicts
of strings: places and transitions are numbers, templates are compiled closures.

Transitions are numbered in firing rank: higher ``priority`` first, then document order. That
number is the conflict rule (docs/petri-nets.md): among enabled transitions the lowest fires.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

from petri_nets.model import REQUIRED, NetDoc
from petri_nets.pnml import write_pnml
from petri_nets.templates import Render, compile_json, compile_value

__all__ = ["Action", "CompiledNet", "Condition", "compile_net"]

IMMEDIATE = "immediate"


@dataclass(slots=True)
class Action:
    kind: str
    type: str | None
    destination: str | None
    body: Render
    net: str | None
    seconds: Render | None
    list: str | None
    var: str | None
    order: str | None


@dataclass(slots=True)
class Condition:
    kind: str  # immediate, message, timer, net_ended, guard
    type: str | None = None
    matches: tuple[tuple[str, Render], ...] = ()
    binds: tuple[tuple[str, str], ...] = ()
    net: str | None = None
    outcome: str | None = None
    var: str | None = None
    test: str | None = None
    value: Render | None = None


@dataclass(slots=True, eq=False)
class CompiledNet:
    name: str
    doc: NetDoc
    version: str
    params: dict[str, Any]
    place_ids: tuple[str, ...]
    initial: tuple[int, ...]
    final: tuple[bool, ...]
    failed: tuple[bool, ...]
    actions: tuple[Action | None, ...]
    is_timer: tuple[bool, ...]
    trans_ids: tuple[str, ...]
    inputs: tuple[tuple[tuple[int, int], ...], ...]
    outputs: tuple[tuple[tuple[int, int], ...], ...]
    conditions: tuple[Condition, ...]
    ready_based: tuple[bool, ...]
    downstream: tuple[tuple[int, ...], ...]
    by_type: dict[str, tuple[int, ...]]
    by_child: dict[str, tuple[int, ...]]
    guards: tuple[int, ...]
    initial_places: tuple[int, ...]


def _condition(spec: Any) -> Condition:
    if spec is None:
        return Condition(IMMEDIATE)
    return Condition(
        kind=spec.kind,
        type=spec.type,
        matches=tuple((m.field, compile_value(m.value)) for m in spec.matches),
        binds=tuple(spec.binds),
        net=spec.net,
        outcome=spec.outcome,
        var=spec.var,
        test=spec.test,
        value=compile_value(spec.value) if spec.value is not None else None,
    )


def compile_net(doc: NetDoc, name: str | None = None) -> CompiledNet:
    """Compile a net that ``validate`` accepted (behaviour is undefined otherwise)."""
    places = doc.places
    pindex = {p.id: i for i, p in enumerate(places)}
    order = sorted(range(len(doc.transitions)), key=lambda i: (-doc.transitions[i].priority, i))
    transitions = [doc.transitions[i] for i in order]
    tindex = {t.id: i for i, t in enumerate(transitions)}
    ins: list[list[tuple[int, int]]] = [[] for _ in transitions]
    outs: list[list[tuple[int, int]]] = [[] for _ in transitions]
    for arc in doc.arcs:
        if arc.source in pindex and arc.target in tindex:
            ins[tindex[arc.target]].append((pindex[arc.source], arc.weight))
        elif arc.source in tindex and arc.target in pindex:
            outs[tindex[arc.source]].append((pindex[arc.target], arc.weight))
    actions: list[Action | None] = []
    for place in places:
        spec = place.action
        if spec is None:
            actions.append(None)
            continue
        body = compile_json(spec.body)[1] if spec.kind in ("publish", "run") else (lambda e: {})
        actions.append(
            Action(
                kind=spec.kind,
                type=spec.type,
                destination=spec.destination,
                body=body,
                net=spec.net,
                seconds=compile_value(spec.seconds) if spec.seconds else None,
                list=spec.list,
                var=spec.var,
                order=spec.order,
            )
        )
    conditions = tuple(_condition(t.condition) for t in transitions)
    ready_based = tuple(c.kind in (IMMEDIATE, "timer", "guard") for c in conditions)
    downstream: list[list[int]] = [[] for _ in places]
    by_type: dict[str, list[int]] = {}
    by_child: dict[str, list[int]] = {}
    for ti, cond in enumerate(conditions):
        if ready_based[ti]:
            for p, _ in ins[ti]:
                if ti not in downstream[p]:
                    downstream[p].append(ti)
        elif cond.kind == "message":
            by_type.setdefault(cond.type or "", []).append(ti)
        elif cond.kind == "net_ended":
            by_child.setdefault(cond.net or "", []).append(ti)
    return CompiledNet(
        name=name or doc.id,
        doc=doc,
        version=hashlib.sha256(write_pnml(doc)).hexdigest()[:16],
        params={p.name: p.default for p in doc.params},
        place_ids=tuple(p.id for p in places),
        initial=tuple(p.initial for p in places),
        final=tuple(p.final for p in places),
        failed=tuple(p.final and p.outcome == "failed" for p in places),
        actions=tuple(actions),
        is_timer=tuple(a is not None and a.kind == "timer" for a in actions),
        trans_ids=tuple(t.id for t in transitions),
        inputs=tuple(tuple(x) for x in ins),
        outputs=tuple(tuple(x) for x in outs),
        conditions=conditions,
        ready_based=ready_based,
        downstream=tuple(tuple(sorted(d)) for d in downstream),
        by_type={k: tuple(v) for k, v in by_type.items()},
        by_child={k: tuple(v) for k, v in by_child.items()},
        guards=tuple(i for i, c in enumerate(conditions) if c.kind == "guard"),
        initial_places=tuple(i for i, n in enumerate(p.initial for p in places) if n),
    )


def missing_params(net: CompiledNet, given: dict[str, Any]) -> list[str]:
    return [k for k, v in net.params.items() if v is REQUIRED and k not in given]


__all__ += ["missing_params"]
