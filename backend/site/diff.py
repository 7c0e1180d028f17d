"""A readable difference between two site documents: element by element, field by field.

Elements are matched by their id (robots by name, edges by their two nodes), so moving a
point of interest reads "pois welcome: node hall -> ga1", not as a list shifted by one.
"""

from __future__ import annotations

import json
from typing import Any

__all__ = ["element_key", "site_diff"]

KEYS = {"robots": "name", "edges": None}


def element_key(section: str, item: Any) -> str:
    """An element's identity within its section."""
    if not isinstance(item, dict):
        return json.dumps(item, sort_keys=True)
    if section == "edges":
        return f"{item.get('a')}->{item.get('b')}"
    key = KEYS.get(section, "id")
    value = item.get(key) if key else None
    return str(value) if value is not None else json.dumps(item, sort_keys=True)


def _short(value: Any) -> str:
    text = json.dumps(value, ensure_ascii=False)
    return text if len(text) <= 120 else text[:117] + "..."


def _by_key(section: str, items: Any) -> dict[str, Any]:
    return {element_key(section, i): i for i in items} if isinstance(items, list) else {}


def site_diff(old: dict[str, Any], new: dict[str, Any]) -> list[dict[str, Any]]:
    """Changes from ``old`` to ``new``: {section, key, change, fields, text} each, in the
    order of the sections and of the new document."""
    out: list[dict[str, Any]] = []
    for section in dict.fromkeys([*old, *new]):
        a, b = old.get(section), new.get(section)
        if a == b:
            continue
        if not isinstance(a, list) and not isinstance(b, list):
            out.append(
                {
                    "section": section,
                    "key": "",
                    "change": "changed",
                    "fields": [{"field": section, "before": a, "after": b}],
                    "text": f"{section}: {_short(a)} -> {_short(b)}",
                }
            )
            continue
        before, after = _by_key(section, a), _by_key(section, b)
        for key, item in after.items():
            if key not in before:
                out.append(_entry(section, key, "added", []))
            elif before[key] != item:
                old_item, new_item = before[key], item
                fields = [
                    {"field": f, "before": old_item.get(f), "after": new_item.get(f)}
                    for f in dict.fromkeys([*old_item, *new_item])
                    if old_item.get(f) != new_item.get(f)
                ]
                out.append(_entry(section, key, "changed", fields))
        for key in before:
            if key not in after:
                out.append(_entry(section, key, "removed", []))
        if list(before) != list(after) and set(before) == set(after):
            out.append(_entry(section, "(order)", "reordered", []))
    return out


def _entry(section: str, key: str, change: str, fields: list[dict[str, Any]]) -> dict[str, Any]:
    if change == "changed":
        parts = "; ".join(
            f"{f['field']} {_short(f['before'])} -> {_short(f['after'])}" for f in fields
        )
        text = f"{section} {key}: {parts}"
    else:
        text = f"{section} {key}: {change}"
    return {"section": section, "key": key, "change": change, "fields": fields, "text": text}
