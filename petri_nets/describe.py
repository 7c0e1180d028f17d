"""A net as JSON for monitors: the whole structure once (with a version), then the live
marking comes from petri_net_event deltas. What a GUI needs to draw a net and light it up."""

from __future__ import annotations

from typing import Any

from petri_nets.compiled import CompiledNet
from petri_nets.model import REQUIRED
from petri_nets.xmlsafe import Node

__all__ = ["describe"]


def _position(graphics: Node | None) -> dict[str, float] | None:
    position = graphics.find("position") if graphics is not None else None
    if position is None:
        return None
    try:
        return {"x": float(position.attrib["x"]), "y": float(position.attrib["y"])}
    except (KeyError, ValueError):
        return None


def describe(net: CompiledNet) -> dict[str, Any]:
    """Places, transitions (with a one-line condition) and arcs; JSON-ready."""
    doc = net.doc
    places = [
        {
            "id": p.id,
            "name": p.name or p.id,
            "initial": p.initial,
            "final": p.final,
            "outcome": p.outcome if p.final else None,
            "action": p.action.kind if p.action else None,
            "detail": (p.action.type or p.action.net or p.action.seconds) if p.action else None,
            "position": _position(p.graphics),
        }
        for p in doc.places
    ]
    transitions = []
    for t in doc.transitions:
        cond = t.condition
        summary = None
        if cond is not None:
            summary = cond.type or cond.net or cond.var or ""
            if cond.matches:
                summary += " " + " ".join(f"{m.field}={m.value}" for m in cond.matches)
        transitions.append(
            {
                "id": t.id,
                "name": t.name or t.id,
                "condition": cond.kind if cond else None,
                "detail": summary,
                "priority": t.priority,
                "position": _position(t.graphics),
            }
        )
    return {
        "net": net.name,
        "version": net.version,
        "plain": net.plain,  # another tool's net: no actions or conditions, ends when dead
        "final_markings": [m.counts for m in doc.final_markings],
        "description": doc.description,
        "params": {k: (None if v is REQUIRED else v) for k, v in net.params.items()},
        "required": [k for k, v in net.params.items() if v is REQUIRED],
        "places": places,
        "transitions": transitions,
        "arcs": [
            {"id": a.id, "source": a.source, "target": a.target, "weight": a.weight}
            for a in doc.arcs
        ],
    }
