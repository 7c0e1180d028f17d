"""``${name.path}`` templates in message fields, compiled once when a net is loaded.

A string that is exactly one reference (``"${point}"``) becomes the referenced value with its
type; a string with references inside text is interpolated. References look names up in the
instance's environment (parameters, then variables bound by conditions and actions); a dotted
path walks into dicts (by key) and lists (by index).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterator, Mapping
from typing import Any

__all__ = ["Render", "TemplateError", "compile_json", "compile_value", "references", "resolve"]

REFERENCE = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z0-9_]+)*)\}")

Render = Callable[[Mapping[str, Any]], Any]


class TemplateError(ValueError):
    """A template refers to something missing, or its JSON is malformed."""


def resolve(path: str, env: Mapping[str, Any]) -> Any:
    """The value of a dotted reference; raises TemplateError naming the missing part."""
    root, *rest = path.split(".")
    if root not in env:
        raise TemplateError(f"${{{path}}}: {root!r} is not set")
    value = env[root]
    for part in rest:
        if isinstance(value, Mapping) and part in value:
            value = value[part]
        elif isinstance(value, list) and part.isdigit() and int(part) < len(value):
            value = value[int(part)]
        else:
            raise TemplateError(f"${{{path}}}: no {part!r} in {type(value).__name__}")
    return value


def _compile_string(text: str) -> Render | None:
    """None when the string has no reference (a constant)."""
    matches = list(REFERENCE.finditer(text))
    if not matches:
        return None
    if len(matches) == 1 and matches[0].span() == (0, len(text)):
        path = matches[0].group(1)
        return lambda env: resolve(path, env)

    def interpolate(env: Mapping[str, Any]) -> str:
        return REFERENCE.sub(lambda m: str(resolve(m.group(1), env)), text)

    return interpolate


def compile_value(value: Any) -> Render:
    """Compile a JSON value: constant parts are shared, containers are rebuilt on each render."""
    if isinstance(value, str):
        render = _compile_string(value)
        return render if render is not None else (lambda env: value)
    if isinstance(value, dict):
        items = [(_compile_string(k), k, compile_value(v)) for k, v in value.items()]

        def render_dict(env: Mapping[str, Any]) -> dict[str, Any]:
            return {(str(kr(env)) if kr else k): vr(env) for kr, k, vr in items}

        return render_dict
    if isinstance(value, list):
        parts = [compile_value(v) for v in value]
        return lambda env: [p(env) for p in parts]
    return lambda env: value


def compile_json(text: str) -> tuple[Any, Render]:
    """Parse JSON text (empty means {}) and compile it; raises TemplateError."""
    text = text.strip()
    if not text:
        return {}, lambda env: {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TemplateError(f"invalid JSON: {exc.msg} at column {exc.colno}") from None
    return value, compile_value(value)


def references(value: Any) -> Iterator[str]:
    """Every root name referenced anywhere inside a JSON value (for validation)."""
    if isinstance(value, str):
        for match in REFERENCE.finditer(value):
            yield match.group(1).split(".")[0]
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from references(key)
            yield from references(item)
    elif isinstance(value, list):
        for item in value:
            yield from references(item)


def parse_literal(text: str) -> Any:
    """A parameter value from text: JSON when it parses as JSON, else the text itself."""
    try:
        return json.loads(text)
    except (json.JSONDecodeError, ValueError):
        return text
