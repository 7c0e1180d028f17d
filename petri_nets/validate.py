"""Semantic checks of a net, each problem with its file and line.

Reading (petri_nets.pnml) reports malformed XML and malformed elements; this module reports
what makes a well-formed net wrong: dangling arcs, unknown action or condition kinds, missing or
undeclared parameters, transitions that can never be enabled, no reachable end. The last group
holds for GuideBot task nets only: a plain net from another tool is checked for structure and
runs until no transition is enabled (docs/petri-nets.md, "Nets from other tools").
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable

from petri_nets.model import (
    ACTION_KINDS,
    CONDITION_KINDS,
    GUARD_TESTS,
    REQUIRED,
    NetDoc,
    Problem,
)
from petri_nets.templates import TemplateError, compile_json, references

__all__ = ["BUILTIN_NAMES", "MESSAGE_TYPE", "declared_names", "validate"]

BUILTIN_NAMES = frozenset({"instance_id", "net", "parent"})
MESSAGE_TYPE = re.compile(r"^[a-z][a-z0-9_.]*$")
NET_OUTCOMES = ("done", "failed", "killed", "stuck")


def declared_names(net: NetDoc) -> set[str]:
    """Names templates may use: parameters, variables set by actions and conditions, builtins."""
    names = set(BUILTIN_NAMES) | {p.name for p in net.params}
    for place in net.places:
        if place.action is not None and place.action.var:
            names.add(place.action.var)
            if place.action.kind == "next":
                names.add(f"{place.action.var}_index")
    for trans in net.transitions:
        if trans.condition is not None:
            names.update(var for var, _ in trans.condition.binds)
    return names


def validate(net: NetDoc) -> list[Problem]:
    """Every problem found (empty when the net can run)."""
    out: list[Problem] = []

    def problem(line: int, message: str) -> None:
        out.append(Problem(net.file, line, message))

    names = declared_names(net)

    def check_refs(line: int, where: str, values: Iterable[object]) -> None:
        for value in values:
            for name in references(value):
                if name not in names:
                    problem(line, f"{where}: parameter {name!r} is used but not declared")

    seen: dict[str, int] = {}
    nodes: list[tuple[str, int]] = [(n.id, n.line) for n in net.places]
    nodes += [(n.id, n.line) for n in net.transitions] + [(n.id, n.line) for n in net.arcs]
    for node_id, node_line in nodes:
        if node_id and node_id in seen:
            problem(node_line, f"id {node_id!r} is used twice (first on line {seen[node_id]})")
        seen.setdefault(node_id, node_line)
    param_seen: set[str] = set()
    for param in net.params:
        if param.name in param_seen:
            problem(param.line, f"parameter {param.name!r} is declared twice")
        param_seen.add(param.name)

    places = {p.id: p for p in net.places}
    transitions = {t.id: t for t in net.transitions}
    inputs: dict[str, list[str]] = {t.id: [] for t in net.transitions}
    outputs: dict[str, list[str]] = {t.id: [] for t in net.transitions}
    for arc in net.arcs:
        ends = [
            arc.source in places,
            arc.source in transitions,
            arc.target in places,
            arc.target in transitions,
        ]
        for attr in ("source", "target"):
            ref = getattr(arc, attr)
            if ref not in places and ref not in transitions:
                problem(
                    arc.line, f"arc {arc.id}: dangling {attr} {ref!r} (no such place or transition)"
                )
        if (ends[0] and ends[2]) or (ends[1] and ends[3]):
            problem(arc.line, f"arc {arc.id}: an arc must join a place and a transition")
        elif ends[0] and ends[3]:
            inputs[arc.target].append(arc.source)
        elif ends[1] and ends[2]:
            outputs[arc.source].append(arc.target)

    run_nets: set[str] = set()
    timer_places: set[str] = set()
    for place in net.places:
        action = place.action
        if action is None:
            continue
        where = f"place {place.id}"
        if action.kind not in ACTION_KINDS:
            problem(
                action.line,
                f"{where}: unknown action kind {action.kind!r} "
                f"(expected one of {', '.join(ACTION_KINDS)})",
            )
            continue
        if action.kind in ("publish", "run"):
            try:
                body, _ = compile_json(action.body)
            except TemplateError as exc:
                problem(action.line, f"{where}: {exc}")
                body = {}
            if not isinstance(body, dict):
                problem(action.line, f"{where}: the {action.kind} body must be a JSON object")
            check_refs(action.line, where, [body])
        if action.kind == "publish":
            if not action.type:
                problem(action.line, f"{where}: a publish action needs a type")
            elif not MESSAGE_TYPE.match(action.type):
                problem(action.line, f"{where}: {action.type!r} is not a message type name")
        elif action.kind == "timer":
            timer_places.add(place.id)
            if not action.seconds:
                problem(action.line, f"{where}: a timer action needs seconds")
            else:
                check_refs(action.line, where, [action.seconds])
                if "${" not in action.seconds:
                    try:
                        if float(action.seconds) < 0:
                            raise ValueError
                    except ValueError:
                        problem(
                            action.line,
                            f"{where}: seconds {action.seconds!r} is not a non-negative number",
                        )
        elif action.kind in ("run", "kill"):
            if not action.net:
                problem(action.line, f"{where}: a {action.kind} action needs a net")
            elif action.kind == "run":
                run_nets.add(action.net)
        elif action.kind == "next":
            if not action.list or not action.var:
                problem(action.line, f"{where}: a next action needs list and var")
            elif action.order not in (None, "sequence", "random"):
                problem(action.line, f"{where}: order {action.order!r} is not sequence or random")
            elif action.list not in names:
                problem(action.line, f"{where}: parameter {action.list!r} is used but not declared")

    for marking in net.final_markings:
        for place_id in marking.counts:
            if place_id not in places:
                line = marking.lines.get(place_id, marking.line)
                problem(line, f"final marking: no place {place_id!r}")
    if not net.task:
        # a plain net from another tool: it runs until nothing is enabled, whatever its
        # shape (dead transitions, no marks, a transition without input are its author's call)
        return sorted(out, key=lambda p: p.line)

    blocked: set[str] = set()
    for trans in net.transitions:
        where = f"transition {trans.id}"
        if not inputs[trans.id]:
            problem(trans.line, f"{where} has no input place: it would fire forever")
            blocked.add(trans.id)
        cond = trans.condition
        if cond is None:
            continue
        if cond.kind not in CONDITION_KINDS:
            problem(
                cond.line,
                f"{where}: unknown condition kind {cond.kind!r} "
                f"(expected one of {', '.join(CONDITION_KINDS)})",
            )
            blocked.add(trans.id)
            continue
        if cond.kind == "message":
            if not cond.type:
                problem(cond.line, f"{where}: a message condition needs a type")
            check_refs(cond.line, where, [m.value for m in cond.matches])
        elif cond.kind == "net_ended":
            if not cond.net:
                problem(cond.line, f"{where}: a net_ended condition needs a net")
            elif cond.net not in run_nets:
                problem(cond.line, f"{where} can never be enabled: no place runs net {cond.net!r}")
                blocked.add(trans.id)
            if cond.outcome is not None and cond.outcome not in NET_OUTCOMES:
                problem(
                    cond.line,
                    f"{where}: outcome {cond.outcome!r} is not one of {', '.join(NET_OUTCOMES)}",
                )
        elif cond.kind == "guard":
            if not cond.var or cond.test not in GUARD_TESTS:
                problem(
                    cond.line, f"{where}: a guard needs var and test ({', '.join(GUARD_TESTS)})"
                )
            elif cond.var not in names:
                problem(cond.line, f"{where}: parameter {cond.var!r} is used but not declared")
            if cond.test == "equals":
                if cond.value is None:
                    problem(cond.line, f"{where}: an equals guard needs a value")
                else:
                    check_refs(cond.line, where, [cond.value])
        elif cond.kind == "timer" and not any(p in timer_places for p in inputs[trans.id]):
            problem(
                cond.line,
                f"{where} can never be enabled: a timer condition needs an "
                "input place with a timer action",
            )
            blocked.add(trans.id)

    _check_reachability(net, inputs, outputs, blocked, problem)
    return sorted(out, key=lambda p: p.line)


def _check_reachability(
    net: NetDoc,
    inputs: dict[str, list[str]],
    outputs: dict[str, list[str]],
    blocked: set[str],
    problem: Callable[[int, str], None],
) -> None:
    """Structural over-approximation: a place is markable if marked at start or an output of a
    transition whose input places are all markable. Anything else can never happen."""
    markable = {p.id for p in net.places if p.initial > 0}
    if not markable and net.places:
        problem(net.line, "no place is initially marked: the net would end at once")
    fired: set[str] = set()
    changed = True
    while changed:
        changed = False
        for trans in net.transitions:
            if trans.id in fired or trans.id in blocked:
                continue
            if inputs[trans.id] and all(p in markable for p in inputs[trans.id]):
                fired.add(trans.id)
                changed = True
                markable.update(outputs[trans.id])
    for trans in net.transitions:
        if trans.id not in fired and trans.id not in blocked:
            dead = [p for p in inputs[trans.id] if p not in markable]
            problem(
                trans.line,
                f"transition {trans.id} can never be enabled: input place(s) "
                f"{', '.join(dead)} can never be marked",
            )
    finals = [p for p in net.places if p.final]
    if net.endless:
        return
    if finals:
        if not any(p.id in markable for p in finals):
            problem(
                net.line,
                "no final place is reachable: the net can never end (mark it "
                "<endless/> if it runs until killed)",
            )
    elif markable and not any(not outputs[t.id] and t.id in fired for t in net.transitions):
        problem(
            net.line,
            "no final place is reachable and no transition removes marks: the net "
            "can never end (declare a <final/> place, or <endless/> if it runs until killed)",
        )


def check_params(
    net: NetDoc, given: Iterable[str], *, line: int, file: str, caller: str
) -> list[Problem]:
    """Problems with the parameters a caller passes: missing required ones, unknown ones."""
    given = set(given)
    declared = {p.name: p for p in net.params}
    out = [
        Problem(file, line, f"{caller}: parameter {name!r} is not declared by net {net.id}")
        for name in sorted(given - set(declared))
    ]
    out += [
        Problem(file, line, f"{caller}: missing parameter {p.name!r} of net {net.id}")
        for p in net.params
        if p.default is REQUIRED and p.name not in given
    ]
    return out
