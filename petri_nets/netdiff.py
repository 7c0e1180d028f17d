"""A readable difference between two versions of a net (the editor's history, docs/nets.md):
one line per element added, removed or changed, saying which of its fields changed how.

Arcs are compared by their ends (an arc redrawn between the same nodes is the same arc), and
moves are told apart from changes of behaviour so a reader sees at once what the robot will
do differently.
"""

from __future__ import annotations

import json
from typing import Any

__all__ = ["net_diff"]

_NET_FIELDS = ("name", "description", "endless", "task")
_MOVED = ("x", "y", "points")


def _show(value: Any) -> str:
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    return json.dumps(value, ensure_ascii=False, sort_keys=True, separators=(", ", ": "))


def _flat(prefix: str, value: Any) -> dict[str, Any]:
    """Nested dicts as dotted keys (``action.body``), so a change names its field."""
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for key, item in value.items():
            out.update(_flat(f"{prefix}.{key}" if prefix else key, item))
        return out
    return {prefix: value}


def _changes(old: dict[str, Any], new: dict[str, Any], skip: tuple[str, ...]) -> list[str]:
    a = {k: v for k, v in _flat("", old).items() if k not in skip and v not in (None, [], "")}
    b = {k: v for k, v in _flat("", new).items() if k not in skip and v not in (None, [], "")}
    out = []
    for key in sorted(set(a) | set(b)):
        if a.get(key) != b.get(key):
            was = _show(a[key]) if key in a else "(none)"
            now = _show(b[key]) if key in b else "(none)"
            out.append(f"{key} {was} → {now}")
    return out


def _elements(
    kind: str, old: list[dict[str, Any]], new: list[dict[str, Any]], key: Any
) -> list[str]:
    before = {key(e): e for e in old}
    after = {key(e): e for e in new}
    lines = []
    for k in [k for k in before if k not in after]:
        lines.append(f"- {kind} {k} removed")
    for k in [k for k in after if k not in before]:
        lines.append(f"+ {kind} {k} added")
    for k in [k for k in after if k in before]:
        changed = _changes(before[k], after[k], ("id", "source", "target", *_MOVED))
        if changed:
            lines.append(f"~ {kind} {k}: " + "; ".join(changed))
        elif any(before[k].get(f) != after[k].get(f) for f in _MOVED):
            lines.append(f"~ {kind} {k}: moved")
    return lines


def net_diff(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """What changed from ``old`` to ``new`` (editor documents, ``petri_nets.netjson``); []
    when they are the same net."""
    lines = []
    for field in _NET_FIELDS:
        if old.get(field) != new.get(field):
            lines.append(f"~ net {field} {_show(old.get(field))} → {_show(new.get(field))}")
    lines += _elements("param", old.get("params", []), new.get("params", []), lambda p: p["name"])
    lines += _elements("place", old.get("places", []), new.get("places", []), lambda p: p["id"])
    lines += _elements(
        "transition", old.get("transitions", []), new.get("transitions", []), lambda t: t["id"]
    )
    lines += _elements(
        "arc",
        old.get("arcs", []),
        new.get("arcs", []),
        lambda a: f"{a['source']} → {a['target']}",
    )
    return lines
