"""Every VDA 5050 message sent or accepted is checked against the official JSON schema of its
topic and version (vendored in ``schemas/``, MIT, © VDA: ``schemas/LICENSE.txt``)."""

from __future__ import annotations

import json
import re
from functools import cache
from pathlib import Path
from typing import Any

from jsonschema import Draft202012Validator

__all__ = ["SCHEMA_DIR", "TOPICS", "VERSIONS", "SchemaViolation", "check", "problems", "version_of"]

SCHEMA_DIR = Path(__file__).with_name("schemas")
VERSIONS = ("2.1.0", "3.0.0")
TOPICS = frozenset({"order", "instantActions", "state", "connection", "factsheet", "visualization"})
"""Topics of both versions (3.0.0 adds ``zoneSet`` and ``responses``)."""


class SchemaViolation(ValueError):
    """A VDA 5050 message that its topic's official schema refuses."""


def version_of(message: Any, default: str = "2.1.0") -> str:
    """The schema version for a message: its ``version`` field's major (2.x -> 2.1.0)."""
    version = message.get("version") if isinstance(message, dict) else None
    if isinstance(version, str) and version.startswith("3."):
        return "3.0.0"
    if isinstance(version, str) and version.startswith("2."):
        return "2.1.0"
    return default


@cache
def _validator(version: str, topic: str) -> Draft202012Validator:
    if version not in VERSIONS:
        raise ValueError(f"unknown VDA 5050 version {version!r} (expected one of {VERSIONS})")
    path = SCHEMA_DIR / version / f"{topic}.schema"
    if not path.is_file():
        raise ValueError(f"VDA 5050 {version} has no topic {topic!r}")
    return Draft202012Validator(_read(path.read_text(encoding="utf-8")))


_TRAILING_COMMA = re.compile(r",(\s*[}\]])")


def _read(text: str) -> Any:
    """A schema file's JSON. The official 3.0.0 ``order``, ``factsheet`` and ``visualization``
    schemas have commas before a closing brace (not JSON: ``json.loads`` refuses them); the
    files stay unchanged and are read with those commas dropped."""
    try:
        return json.loads(text)
    except ValueError:
        return json.loads(_TRAILING_COMMA.sub(r"\1", text))


def problems(topic: str, message: Any, version: str | None = None) -> list[str]:
    """What the official schema of ``topic`` finds wrong with ``message`` (empty: valid), each
    as ``path: reason``; ``version`` defaults to the message's own."""
    validator = _validator(version or version_of(message), topic)
    found = []
    for error in sorted(validator.iter_errors(message), key=lambda e: list(e.absolute_path)):
        where = "/".join(str(p) for p in error.absolute_path) or "(message)"
        found.append(f"{where}: {error.message}")
    return found


def check(topic: str, message: Any, version: str | None = None) -> None:
    """Raise SchemaViolation naming the topic and every problem, else return."""
    found = problems(topic, message, version)
    if found:
        shown = "; ".join(found[:5]) + (f"; and {len(found) - 5} more" if len(found) > 5 else "")
        raise SchemaViolation(f"{topic} refused by the VDA 5050 schema: {shown}")
